"""solver=srv|cmaes|dls behind one contract; the Levenberg-Marquardt routine; batch-level stopping."""

from __future__ import annotations

import math

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.least_squares import LMOptions, Prior, levenberg_marquardt
from graspnet_torch.paths import repo_root
from graspnet_torch.settings import build, unset
from graspnet_torch.solver import SolverCfg
from graspnet_torch.solver.loop import enough_succeeded


def test_levenberg_marquardt_agrees_with_least_squares_on_a_linear_map():
    """f(x) = A x with a reachable goal: every row lands on the exact solution; an overdetermined
    unreachable goal: LM ends at torch.linalg.lstsq's minimiser (bounds inactive)."""
    g = torch.Generator().manual_seed(0)
    A = torch.randn(6, 3, generator=g, dtype=torch.float64)
    x_true = torch.rand(4, 3, generator=g, dtype=torch.float64) - 0.5
    lo, hi = torch.full((3,), -10.0, dtype=torch.float64), torch.full((3,), 10.0, dtype=torch.float64)

    def f(x, rows):
        return x @ A.T, A.expand(x.shape[0], 6, 3)

    out = levenberg_marquardt(f, x_true @ A.T, torch.zeros(4, 3, dtype=torch.float64), lo, hi, 50)
    assert torch.allclose(out.x, x_true, atol=1e-6) and bool((out.err < 1e-6).all())
    goal = torch.randn(6, generator=g, dtype=torch.float64)  # 6 equations, 3 unknowns: no exact solution
    out = levenberg_marquardt(f, goal, torch.zeros(1, 3, dtype=torch.float64), lo, hi, 200)
    ref = torch.linalg.lstsq(A, goal.unsqueeze(1)).solution.squeeze(1)
    assert torch.allclose(out.x[0], ref, atol=1e-5)


def test_levenberg_marquardt_respects_bounds_never_worsens_and_stops_rows():
    """A goal outside the box: x stays within it and ends at the bound; |e| never rises (trace);
    a row that starts within tol takes no step; ``done`` stops the others."""
    def f(x, rows):
        return x.clone(), torch.eye(2, dtype=x.dtype).expand(x.shape[0], 2, 2)

    goal = torch.tensor([2.0, 0.5], dtype=torch.float64)
    lo, hi = torch.zeros(2, dtype=torch.float64), torch.ones(2, dtype=torch.float64)
    x0 = torch.tensor([[0.1, 0.1], [1.0, 0.5]], dtype=torch.float64)
    trace = []
    out = levenberg_marquardt(f, goal, x0, lo, hi, 40, LMOptions(tol=1.0 + 1e-9, trace=trace))
    assert bool(((out.x >= lo) & (out.x <= hi)).all())
    assert out.steps[1] == 0  # |e| = 1: within tol from the start
    assert out.x[0, 0] == pytest.approx(1.0) and out.x[0, 1] == pytest.approx(0.5, abs=1e-6)
    errs = torch.stack(trace)
    assert bool((errs[1:] <= errs[:-1] + 1e-15).all())
    never = levenberg_marquardt(f, goal, x0, lo, hi, 40, LMOptions(done=lambda stopped: torch.ones_like(stopped)))
    assert never.steps.tolist() == [0, 0]


def test_levenberg_marquardt_stops_a_row_settled_in_a_local_minimum():
    """Rosenbrock's residuals (10 (y - x^2), 1 - x) plus a third the model cannot move: toward a
    third goal of 1 the error cannot fall below 1 and the row creeps there; with ``min_gain`` it
    stops once a step gains less than that fraction, within that fraction of where the whole
    budget ends. Toward 0 the row converges to (1, 1), not cut short."""
    def f(p, rows):
        x, y = p[:, 0], p[:, 1]
        value = torch.stack([10 * (y - x * x), 1 - x, torch.zeros_like(x)], -1)
        J = torch.zeros(p.shape[0], 3, 2, dtype=p.dtype)
        J[:, 0, 0], J[:, 0, 1], J[:, 1, 0] = -20 * x, 10.0, -1.0
        return value, J

    goal = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    lo, hi = torch.full((2,), -5.0, dtype=torch.float64), torch.full((2,), 5.0, dtype=torch.float64)
    x0 = torch.tensor([[-1.2, 1.0], [-1.2, 1.0]], dtype=torch.float64)
    full = levenberg_marquardt(f, goal, x0, lo, hi, 200, LMOptions(tol=1e-12, lam_max=1e4))
    cut = levenberg_marquardt(f, goal, x0, lo, hi, 200, LMOptions(tol=1e-12, lam_max=1e4, min_gain=1e-3))
    assert int(cut.steps[0]) < 40 and int(full.steps[0]) == 200
    assert float(cut.err[0]) == pytest.approx(float(full.err[0]), rel=2e-3) and float(full.err[0]) >= 1.0
    assert float(cut.err[1]) < 1e-9 and cut.x[1].tolist() == pytest.approx([1.0, 1.0])
    assert int(cut.steps[1]) == int(full.steps[1])


def test_levenberg_marquardt_with_a_prior_lands_nearest_the_centre():
    """A linear model with more unknowns than equations (x in R^3, A x = g in R^1): the solutions
    form a plane. With a prior toward c whose weight fades (the continuation of
    FingerEnvironment.centre), the row lands on the solution nearest c (recomputed in closed
    form: c + A^T (A A^T)^-1 (g - A c)); without one, on the nearest to its start. The result's
    error is the model's alone."""
    A = torch.tensor([[1.0, 2.0, -1.0]], dtype=torch.float64)

    def f(x, rows):
        return x @ A.T, A.expand(x.shape[0], 1, 3)

    goal, c = torch.tensor([1.0], dtype=torch.float64), torch.tensor([0.5, -0.5, 2.0], dtype=torch.float64)
    lo, hi = torch.full((3,), -10.0, dtype=torch.float64), torch.full((3,), 10.0, dtype=torch.float64)
    x = x0 = torch.zeros(1, 3, dtype=torch.float64)
    for k in range(6):
        weight = torch.full((3,), 1.0 / 3 ** k, dtype=torch.float64)
        out = levenberg_marquardt(f, goal, x, lo, hi, 50, prior=Prior(c, weight))
        assert out.value.shape == (1, 1) and float(out.err[0]) == pytest.approx(float((goal - out.x @ A.T).abs()[0]))
        x = out.x
    x = levenberg_marquardt(f, goal, x, lo, hi, 50, LMOptions(tol=1e-12)).x
    nearest_c = c + A[0] * (goal - A @ c) / (A @ A.T)[0]
    assert x[0].tolist() == pytest.approx(nearest_c.tolist(), abs=1e-9)
    plain = levenberg_marquardt(f, goal, x0, lo, hi, 50, LMOptions(tol=1e-12)).x
    assert plain[0].tolist() == pytest.approx((A[0] * goal / (A @ A.T)[0]).tolist(), abs=1e-6)


def test_levenberg_marquardt_stops_evaluating_a_row_refused_at_the_largest_damping():
    """A row whose goal lies outside the box ends at the bound; once its step is refused at
    lam_max (the same step would come again) the model no longer sees it, yet its steps and the
    trace count the whole budget; a row that can still move keeps being evaluated."""
    seen = []

    def f(x, rows):
        seen.append(rows.clone())
        return x.clone(), torch.eye(1, dtype=x.dtype).expand(x.shape[0], 1, 1)

    goal = torch.tensor([[2.0], [0.5]], dtype=torch.float64)  # row 0: out of [0, 1]; row 1: inside
    lo, hi = torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.float64)
    x0 = torch.tensor([[1.0], [0.0]], dtype=torch.float64)
    trace = []
    out = levenberg_marquardt(f, goal, x0, lo, hi, 40, LMOptions(lam=0.5, lam_max=1.0, trace=trace))
    assert out.steps.tolist() == [40, 40] and len(trace) == 40
    assert out.x[0, 0] == 1.0 and float(out.err[0]) == pytest.approx(1.0)
    assert sum(int((r == 0).sum()) for r in seen[1:]) <= 2  # row 0: refused at 0.5 * 4 -> lam_max, then dropped
    assert sum(int((r == 1).sum()) for r in seen[1:]) >= 10


def test_enough_succeeded_counts_per_problem():
    succeeded = torch.tensor([True, False, False, False, True, True])
    pid = torch.tensor([0, 0, 1, 1, 2, 2])
    assert enough_succeeded(succeeded, pid, 1).tolist() == [True, True, False, False, True, True]
    assert enough_succeeded(succeeded, pid, 2).tolist() == [False, False, False, False, True, True]
    assert enough_succeeded(succeeded, None, 3).tolist() == [True] * 6


@pytest.mark.parametrize("name", ["srv", "cmaes", "dls", "paper"])
def test_every_solver_config_composes_into_its_settings(name):
    with initialize_config_dir(config_dir=str(repo_root() / "configs"), version_base=None):
        cfg = compose("solve_grasp", overrides=[f"solver={name}"])
    solver = build(SolverCfg, unset(SolverCfg, OmegaConf.to_container(cfg.solver)), "solver")  # null: the robot's
    assert solver.method == {"paper": "srv"}.get(name, name)
    if name == "paper":  # the command line's paper protocol is the Python one
        assert solver == SolverCfg.paper()
        assert solver.stop_rule == "reinforcement" and solver.stop is None and solver.polish.mode == "fingers"
    else:
        assert solver.stop_rule == "grasp" and solver.tolerance_mm == 1.0
    if name == "srv":  # every default in one place: the group lists the dataclass's values
        assert solver == SolverCfg()


def test_the_default_solver_lands_random_problems_below_a_micrometre(hand):
    """srv with the whole polish: random reachable 2-5 finger problems end below 1 mm (measured:
    every one of 100, median 4e-5 mm); the problem ends at its first success."""
    for seed in range(4):
        problem = gt.random_reachable_problem(hand, seed)
        result = gt.solve(problem, trials=8, seed=0)
        assert result.total_error_mm < 1.0, (seed, result.total_error_mm)
        stopped_at = result.best.iterations
        assert all(t.iterations <= stopped_at for t in result.trials)  # the others stopped with it


@pytest.mark.parametrize("method", ["cmaes", "dls"])
def test_baselines_solve_a_hand_problem_under_the_same_contract(hand, method):
    """Same result JSON, errors recomputed in float64 from the reported configuration."""
    problem = gt.random_reachable_problem(hand, 7, n_fingers=3)
    result = gt.solve(problem, trials=6, seed=1, solver={"method": method, "max_iterations": 600})
    assert result.settings["solver"] == method
    assert result.best.total_error_mm < 1.0
    data = result.to_dict()
    assert {"palm_pose", "joints", "fingertip_error_mm", "total_error_mm", "iterations", "trials"} <= set(data)
    d = math.pi / 180
    pose = torch.tensor(data["palm_pose"][:3] + [a * d for a in data["palm_pose"][3:]], dtype=torch.float64)
    q = hand.finger_joints_from_file(data["joints"])
    tips = hand.fingertips_world(pose, q)
    for contact in problem.contacts:
        err = float((tips[hand.finger_index(contact.finger)] - torch.as_tensor(contact.position)).norm()) * 1000
        assert err == pytest.approx(data["fingertip_error_mm"][contact.finger], abs=1e-6)


def test_dls_refuses_sensor_noise():
    with pytest.raises(ConfigError, match=r"solver=dls .* never sees the reinforcement"):
        gt.solve("glass3", trials=2, noise=0.1, solver={"method": "dls"})


def test_cmaes_learns_from_a_noisy_reward_better_than_its_first_generation():
    """With sigma_n = 0.2 CMA-ES still improves on block5: the configurations it reports are far
    better than its first generation's (its ablation: the search stopped at once); the paper's point
    model, as its noise study."""
    kw = dict(trials=4, seed=0, noise=0.2, reward=gt.RewardCfg(a=10.0))
    cfg = {"method": "cmaes", "threshold": None, "polish": {"mode": "fingers"}, "fingers": {"final_refine": 0},
           "contact_model": "point"}
    long = gt.solve("block5", solver={**cfg, "max_iterations": 600}, **kw)
    short = gt.solve("block5", solver={**cfg, "max_iterations": 9}, **kw)
    med = lambda r: sorted(t.total_error_mm for t in r.trials)[len(r.trials) // 2]  # noqa: E731
    assert med(long) < 0.3 * med(short), (med(long), med(short))
    assert "step_size" in long.outcome.history and long.outcome.history["iteration"][-1] == 600


@pytest.mark.slow
def test_dls_and_cmaes_work_for_the_arm_and_the_manus():
    """Every robot of the one loop: the arm with obstacles (R3, never into a collision the proxy
    sees) and the MANUS (both pairings)."""
    arm = gt.solve("env1", trials=4, seed=0, solver={"method": "dls"})
    assert arm.settings["solver"] == "dls" and arm.best.total_error_mm < 10.0
    cube = gt.solve("cube", trials=4, seed=0, solver={"method": "dls"})
    assert cube.best.distance_mm < 1.0 and len(cube.best.arm_joints) == 9
    cm = gt.solve("cube", trials=2, seed=0, solver={"method": "cmaes", "max_iterations": 60})
    assert cm.settings["solver"] == "cmaes" and len(cm.trials) == 2


def test_the_in_loop_polish_is_off_in_the_paper_protocol():
    """solver=paper runs the loop as the paper's (every iteration of the budget here); the default
    hands glass3's trials to the polish within a few iterations."""
    paper = gt.solve("glass3", trials=3, seed=0, max_iterations=40, solver=SolverCfg.paper(threshold=None))
    assert all(t.iterations == 40 for t in paper.trials)
    fast = gt.solve("glass3", trials=3, seed=0)
    assert fast.best.iterations < 40 and fast.best.total_error_mm < 1.0


def test_a_batch_of_hand_problems_evaluates_as_each_problem_alone(hand):
    """The batch environment (union of fingers, per-trial contacts, a mask) gives each trial the
    error its own problem's environment gives (batched == looped)."""
    from graspnet_torch.solver.api import build_environment, robot_and_ik

    _, ik = robot_and_ik("hand")
    problems = [gt.random_reachable_problem(hand, s, n_fingers=k) for s, k in ((1, 2), (2, 4), (3, 3))]
    cfg = SolverCfg()
    batch = build_environment(hand, problems, ik, cfg, torch.float64, runs=2)
    g = torch.Generator().manual_seed(0)
    config = batch.lower + (batch.upper - batch.lower) * torch.rand(6, 6, generator=g, dtype=torch.float64)
    ev = batch.evaluate(config)
    for k, p in enumerate(problems):
        alone = build_environment(hand, p, ik, cfg, torch.float64).evaluate(config[2 * k: 2 * k + 2])
        assert torch.allclose(ev.error[2 * k: 2 * k + 2], alone.error, rtol=1e-9, atol=1e-12)
        cols = [batch.fingers.index(f) for f in p.fingers]
        assert torch.allclose(ev.finger_errors[2 * k: 2 * k + 2, cols], alone.finger_errors, atol=1e-12)
        unused = [c for c in range(len(batch.fingers)) if c not in cols]
        assert bool((ev.finger_errors[2 * k: 2 * k + 2, unused] == 0).all())
    some = torch.tensor([5, 0])  # a subset of trials, out of order
    part = batch.evaluate(config[some], some)
    assert torch.allclose(part.error, ev.error[some], rtol=1e-9, atol=1e-12)


def test_solve_many_solves_mixed_hand_problems_in_one_batch(hand):
    """Problems with different contact fingers in one vectorised search: each result lists its
    own fingers, its errors are forward kinematics of its reported configuration, the fingers it
    does not use stay at home, and every problem lands below 1 mm."""
    problems = [gt.random_reachable_problem(hand, s) for s in range(6)]
    results = gt.solve_many(problems, trials=3, seed=0)
    home = hand.home_posture(torch.float64).fingers
    d = math.pi / 180
    for p, r in zip(problems, results, strict=True):
        assert set(r.fingertip_error_mm) == set(p.fingers) and len(r.trials) == 3
        assert r.total_error_mm < 1.0
        pose = torch.tensor(r.palm_pose[:3] + [a * d for a in r.palm_pose[3:]], dtype=torch.float64)
        q = hand.finger_joints_from_file(r.joints)
        tips = hand.fingertips_world(pose, q)
        for c in p.contacts:
            err = float((tips[hand.finger_index(c.finger)] - torch.as_tensor(c.position)).norm()) * 1000
            assert err == pytest.approx(r.fingertip_error_mm[c.finger], abs=1e-6)
        for f in set(hand.finger_names) - set(p.fingers):
            assert torch.allclose(q[hand.finger_index(f)], home[hand.finger_index(f)])
