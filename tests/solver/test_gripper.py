"""The MANUS's two-point environment (paper section 7) on the one loop: problems with `points` and
`approach`, eq. 24-29 against an independent recomputation, results by joint name."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.robot.robot import Posture
from graspnet_torch.solver import GripperCfg
from graspnet_torch.solver.gripper import GripperEnvironment
from graspnet_torch.solver.search_space import gripper_bounds

CUBE = {"robot": "manus", "object": {"shape": "box", "size": [0.06, 0.06, 0.06], "pose": [0.9, 0.2, 0.75, 0, 0, 30]},
        "points": [[0.0, 0.03, 0.0], [0.0, -0.03, 0.0]]}


@pytest.fixture(scope="module")
def manus():
    return gt.load_robot("manus")


def test_evaluation_is_eq_24_to_28_of_forward_kinematics(manus):
    """d = min of the two pairings' summed distances and |n_g . n_o|, with the gripper points from
    pytorch-kinematics link frames (float64)."""
    problem = gt.GraspProblem.from_mapping(CUBE, source="cube")
    env = GripperEnvironment(manus, problem, gt.SolverCfg(gripper=GripperCfg(settle=0)), dtype=torch.float64)
    assert env.n == 9
    g = torch.Generator().manual_seed(0)
    q = env.lower + (env.upper - env.lower) * torch.rand(5, 9, generator=g, dtype=torch.float64)
    ev = env.evaluate(q)
    target = problem.points_world()
    for k in range(5):
        frames = manus.link_frames(Posture(palm_pose=torch.zeros(6), fingers=torch.zeros(0, 0), body=q[k]))
        p1, p2 = (frames[name][:3, 3] for name in manus.cfg.gripper_points)
        d1 = np.linalg.norm(target[0] - p1) + np.linalg.norm(target[1] - p2)
        d2 = np.linalg.norm(target[1] - p1) + np.linalg.norm(target[0] - p2)
        n_g, n_o = (p2 - p1) / np.linalg.norm(p2 - p1), (target[1] - target[0]) / np.linalg.norm(target[1] - target[0])
        assert float(ev.error[k]) == pytest.approx(min(d1, d2), abs=1e-6)  # pk holds URDF origins in float32
        assert float(ev.alignment[k]) == pytest.approx(abs(n_g @ n_o), abs=1e-6)
    r = gt.rewards.Reward(gt.RewardCfg(), 2000, env.reward_base)(ev, 1)
    expected = (ev.alignment + 1 - torch.tanh(ev.error)) / 2  # eq. 29 with a = 1
    assert torch.allclose(r, expected)


def test_approach_bounds_the_search_within_the_limits(manus):
    data = {**CUBE, "approach": {"base_x": 0.45, "shoulder_pitch": 20.0}}
    problem = gt.GraspProblem.from_mapping(data, source="cube")
    lo, hi = gripper_bounds(manus, problem, approach_m=0.2, approach_deg=30.0)
    names = manus.body_joint_names
    x, pitch = names.index("base_x"), names.index("shoulder_pitch")
    limits = manus.body_limits
    assert (lo[x], hi[x]) == pytest.approx((0.25, limits[1][x]))  # 0.45 + 0.2 clipped to the limit 0.5
    assert (lo[pitch], hi[pitch]) == pytest.approx((math.radians(-10), math.radians(50)))
    free = names.index("wrist_roll")
    assert (lo[free], hi[free]) == pytest.approx((limits[0][free], limits[1][free]))


@pytest.mark.parametrize(("change", "message"), [
    ({"contacts": [{"finger": "thumb", "position": [0, 0, 0]}]}, "'contacts' (one point per finger) does not apply"),
    ({"points": [[0, 0, 0]]}, "needs exactly 2 object points"),
    ({"points": [[0, 0, 0], [0, 0, 0], [0, 0, 1]]}, "needs exactly 2 object points"),
    ({"points": [[0, 0, 0], [0, 0, 0.00001]]}, "the two points are at the same place"),
    ({"points": [[0, 0, "x"], [0, 0, 1]]}, "points[0][2]: expected a number"),
    ({"bounds": {"min": [0] * 9, "max": [1] * 9}}, "'bounds' (an arm's joint ranges) does not apply to robot 'manus'"),
])
def test_bad_gripper_problems_are_refused(change, message):
    with pytest.raises(gt.ProblemError) as info:
        gt.GraspProblem.from_mapping({**CUBE, **change}, source="cube")
    assert message in str(info.value)


@pytest.mark.parametrize(("approach", "message"), [
    ({"base_z": 0.1}, "approach: unknown joint(s) base_z"),
    ({"shoulder_pitch": 120.0}, "approach.shoulder_pitch: 120 lies outside its limits [-90, 90] degrees"),
])
def test_bad_approach_is_refused(manus, approach, message):
    problem = gt.GraspProblem.from_mapping({**CUBE, "approach": approach}, source="cube")
    with pytest.raises(gt.ProblemError) as info:
        GripperEnvironment(manus, problem, gt.SolverCfg())
    assert message in str(info.value)


@pytest.mark.slow
def test_solve_reports_the_interface_fields_recomputable_from_the_urdf(manus):
    problem = gt.GraspProblem.from_mapping(CUBE, source="cube")
    result = gt.solve(problem, trials=3, seed=0, max_iterations=30)
    data = json.loads(result.to_json())
    for key in ("arm_joints", "distance_mm", "alignment", "gripper_points", "collisions", "success", "iterations",
                "reinforcement", "wall_time_s", "trials"):
        assert key in data, key
    assert "joints" not in data and "total_error_mm" not in data
    assert list(data["arm_joints"]) == list(manus.body_joint_names)
    q = torch.tensor([v * (math.pi / 180 if kind == "revolute" else 1.0)
                      for v, kind in zip(data["arm_joints"].values(), manus.body.joint_types, strict=True)],
                     dtype=torch.float64)
    points = manus.gripper_points(q)
    assert torch.allclose(points, torch.tensor(data["gripper_points"], dtype=torch.float64), atol=1e-9)
    target = torch.as_tensor(problem.points_world())
    d = min(float((target - points).norm(dim=-1).sum()), float((target.flip(0) - points).norm(dim=-1).sum()))
    assert data["distance_mm"] == pytest.approx(d * 1000, abs=1e-6)


def test_polish_lands_from_random_starts(manus):
    """The Levenberg-Marquardt polish (active set at the joint limits, both pairings) alone brings
    random configurations onto a reachable pair of points: d < 1 mm for most (32/40 measured
    here; 199/200 on the cube task), and never further than it started."""
    q0 = torch.tensor([[0.1, -0.2, 0.3, 0.5, 0.4, -1.0, 0.7, 0.2, -0.4]], dtype=torch.float64)
    points = manus.gripper_points(q0)[0].tolist()
    problem = gt.GraspProblem.from_mapping({"robot": "manus", "points": points}, source="reachable")
    cfg = gt.SolverCfg(gripper=GripperCfg(settle=0, polish_iterations=200))
    env = GripperEnvironment(manus, problem, cfg, dtype=torch.float64)
    g = torch.Generator().manual_seed(5)
    starts = env.lower + (env.upper - env.lower) * torch.rand(40, 9, generator=g, dtype=torch.float64)
    before = env.evaluate(starts)
    q, ev = env.finish(starts, before)
    assert float((ev.error < 1e-3).double().mean()) >= 0.75
    assert bool((ev.error <= before.error + 1e-12).all())  # never worse
    assert bool(((q >= env.lower - 1e-12) & (q <= env.upper + 1e-12)).all())


@pytest.mark.slow
def test_polish_and_refine_never_step_into_a_collision(manus):
    """With collisions counted, a polish step that raises the proxy's count is refused: starts
    that are clear stay clear."""
    problem = gt.GraspProblem.from_task("cube")
    cfg = gt.SolverCfg(gripper=GripperCfg(settle=0, polish_iterations=100))  # the polish alone
    env = GripperEnvironment(manus, problem, cfg, dtype=torch.float64, collisions=True)
    g = torch.Generator().manual_seed(6)
    starts = env.lower + (env.upper - env.lower) * torch.rand(60, 9, generator=g, dtype=torch.float64)
    before = env.evaluate(starts)
    q, ev = env.finish(starts, before)
    clear = before.collisions == 0
    assert int(clear.sum()) >= 10
    assert bool((env.settled(q, settle=False).collisions[clear] == 0).all())
    assert bool((ev.error <= before.error + 1e-12).all())


def test_refine_steps_are_evaluated_and_reported(manus):
    """With solver.refine, the environment evaluates (and the loop reports) the settled
    configuration, which is closer than the proposal."""
    problem = gt.GraspProblem.from_mapping(CUBE, source="cube")
    plain = GripperEnvironment(manus, problem, gt.SolverCfg(gripper=GripperCfg(settle=0)))
    refined = GripperEnvironment(manus, problem, gt.SolverCfg(gripper=GripperCfg(settle=2)))
    g = torch.Generator().manual_seed(7)
    q = plain.lower + (plain.upper - plain.lower) * torch.rand(50, 9, generator=g)
    ev0, ev2 = plain.evaluate(q), refined.evaluate(q)
    assert ev0.config is q and not torch.equal(ev2.config, q)  # the proposal as given; the settled one
    assert bool((ev2.error <= ev0.error + 1e-6).all()) and float(ev2.error.mean()) < 0.7 * float(ev0.error.mean())
    assert torch.allclose(plain.evaluate(ev2.config).error, ev2.error, atol=1e-6)


def _cube_at(x: float, y: float) -> gt.GraspProblem:
    """The cube of task ``cube`` moved to (x, y) with its table (the protocol's layout)."""
    return gt.GraspProblem.from_mapping({
        "robot": "manus", "object": {"shape": "box", "size": [0.07, 0.07, 0.07], "pose": [x, y, 0.755, 0, 0, 0]},
        "points": [[0.0, 0.035, 0.0], [0.0, -0.035, 0.0]],
        "obstacles": [{"shape": "box", "size": [0.6, 1.2, 0.72], "pose": [x + 0.2, y, 0.36, 0, 0, 0]}]},
        source=f"cube@{x},{y}")


def test_a_batch_of_problems_evaluates_as_each_problem_alone(manus):
    """A batch environment (3 problems x 4 trials, one proxy holding every table and cube) gives
    each trial the evaluation its own problem's environment gives; a subset of trials (the loop's
    active ones) gives the same rows."""
    problems = [_cube_at(0.7, -0.3), _cube_at(0.9, 0.1), _cube_at(1.1, 0.4)]
    settle2 = gt.SolverCfg(gripper=GripperCfg(settle=2))
    batch = GripperEnvironment(manus, problems, settle2, dtype=torch.float64, collisions=True, runs=4)
    assert batch.lower.shape == (12, 9) and batch.problem_index.tolist() == [0] * 4 + [1] * 4 + [2] * 4
    g = torch.Generator().manual_seed(8)
    q = batch.lower + (batch.upper - batch.lower) * torch.rand(12, 9, generator=g, dtype=torch.float64)
    q[:, 0] = 0.3  # the base near the tables: some collide
    ev = batch.evaluate(q)
    for k, problem in enumerate(problems):
        alone = GripperEnvironment(manus, problem, settle2, dtype=torch.float64, collisions=True)
        rows = slice(4 * k, 4 * k + 4)
        one = alone.evaluate(q[rows])
        assert torch.allclose(one.error, ev.error[rows]) and torch.equal(one.collisions, ev.collisions[rows])
        assert torch.allclose(one.config, ev.config[rows])
    assert int((ev.collisions > 0).sum()) > 0
    idx = torch.tensor([1, 6, 11])
    part = batch.evaluate(q[idx], idx)
    assert torch.allclose(part.error, ev.error[idx]) and torch.equal(part.collisions, ev.collisions[idx])


@pytest.mark.slow
def test_solve_many_gives_each_problem_its_result(manus):
    """One vectorised loop over two problems: a result per problem, in order, whose distance is
    recomputed from its own problem's points and the reported joints."""
    problems = [_cube_at(0.8, -0.2), _cube_at(1.0, 0.3)]
    results = gt.solve_many(problems, trials=3, seed=0, max_iterations=40)
    assert [len(r.trials) for r in results] == [3, 3]
    for problem, result in zip(problems, results, strict=True):
        assert result.problem == problem.source
        for trial in result.trials:
            q = torch.tensor([v * (math.pi / 180 if kind == "revolute" else 1.0) for v, kind in
                              zip(trial.arm_joints.values(), manus.body.joint_types, strict=True)], dtype=torch.float64)
            points = manus.gripper_points(q)
            target = torch.as_tensor(problem.points_world())
            d = min(float((target - points).norm(dim=-1).sum()), float((target.flip(0) - points).norm(dim=-1).sum()))
            assert trial.distance_mm == pytest.approx(d * 1000, abs=1e-6)


def test_solve_many_refuses_mixed_robots():
    with pytest.raises(gt.ProblemError, match="one batch, one robot"):
        gt.solve_many([_cube_at(0.8, 0.0), "glass3"], trials=1, max_iterations=1)


def test_closed_form_points_and_jacobian_match_the_kernel_and_finite_differences(manus):
    """The gripper points from the chain frames equal the URDF kernel's, and the closed-form
    Jacobian (w x (p - o) per revolute joint, w per prismatic one) equals central differences
    (float64)."""
    problem = gt.GraspProblem.from_mapping(CUBE, source="cube")
    env = GripperEnvironment(manus, problem, gt.SolverCfg(gripper=GripperCfg(settle=0)), dtype=torch.float64)
    g = torch.Generator().manual_seed(10)
    q = env.lower + (env.upper - env.lower) * torch.rand(6, 9, generator=g, dtype=torch.float64)
    _levels, points, J = env.kinematics(q, jacobian=True)
    assert torch.allclose(points, manus.gripper_points(q), atol=1e-7)
    h, eye = 1e-6, torch.eye(9, dtype=torch.float64)
    fd = torch.stack([(manus.gripper_points(q + h * eye[k]) - manus.gripper_points(q - h * eye[k])).reshape(6, 6)
                      / (2 * h) for k in range(9)], dim=-1)
    assert torch.allclose(J, fd, atol=1e-7)


@pytest.mark.slow
def test_learners_near_a_grasp_are_polished_inside_the_loop_and_stop(manus):
    """Every learner of the protocol runs to its own stop (``stop: null``): with the in-loop polish
    (the default, as a hand's) the learners land and stop within a few hundred iterations, where
    without it (``polish.from_r: null``) they jitter a few mm from the grasp until the budget ends;
    both end on grasps (the polish after the loop), the in-loop one no worse."""
    from dataclasses import replace

    from graspnet_torch.tasks.manus import cube_problem, protocol_positions

    problems = [cube_problem(x, y) for x, y in protocol_positions()[::16]]
    cfg = gt.SolverCfg(stop=None, start="random")
    inside = gt.solve_many(problems, trials=4, seed=0, solver=cfg)
    after = gt.solve_many(problems, trials=4, seed=0, solver=replace(cfg, polish=replace(cfg.polish, from_r=None)))
    its = [np.median([t.iterations for t in r.trials]) for r in (inside + after)]
    assert max(its[:4]) < 300 and min(its[4:]) == 2000
    solved = [sum(t.success for r in rs for t in r.trials) for rs in (inside, after)]
    assert solved[0] >= solved[1] >= 12
