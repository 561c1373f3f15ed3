"""Posture proposals: learned (beats random starts and its own untrained initialisation on fresh
problems), equivariant for a free hand, validated on load, and the loop starts exactly there."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.errors import CheckpointError
from graspnet_torch.jobs.train_posture import evaluate_proposal
from graspnet_torch.proposal import PostureProposal, ProposalCfg, load_proposal, proposal_of
from graspnet_torch.proposal.checkpoint import posture_checkpoint, save_proposal
from graspnet_torch.solver import api
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.loop import START_MARGIN, run_loop
from graspnet_torch.solver.proposals import proposal_starts, proposals
from graspnet_torch.tasks.objects import random_pose

FRESH = 800_000  # seeds no training run draws


@pytest.fixture(scope="module")
def shipped():
    robot, ik = api.robot_and_ik("hand")
    return robot, ik, proposal_of(robot)


def test_every_shipped_robot_has_a_proposal_model_that_loads():
    for name in ("hand", "arm_hand", "manus"):
        robot = gt.load_robot(name)
        model = load_proposal(robot)
        assert isinstance(model, PostureProposal) and posture_checkpoint(robot).is_file()


def test_the_trained_model_beats_its_untrained_initialisation(shipped):
    """Best of K proposals on fresh problems (fingers by the FCNN, no iteration): the trained
    model against the same architecture with fresh weights and the same data scales."""
    robot, ik, model = shipped
    fresh = PostureProposal(model.slots, model.n, ProposalCfg(heads=model.heads))
    for name in ("target_mean", "target_std", "config_mean", "config_std", "periodic"):
        getattr(fresh, name).copy_(getattr(model, name))
    trained = evaluate_proposal(model, robot, ik, n=40, seed=FRESH)
    untrained = evaluate_proposal(fresh.eval(), robot, ik, n=40, seed=FRESH)
    assert trained["median_mm"] < 10 and trained["median_mm"] < untrained["median_mm"] / 3
    assert trained["p90_mm"] < untrained["p90_mm"]
    assert trained["median_mm"] < trained["random_median_mm"] / 10  # and random configurations, best of K


def test_proposal_starts_beat_random_starts_in_iterations_and_first_error(shipped):
    """On fresh problems, 4 trials: the first configurations tried (the paper's protocol: no
    polish) are nearer their contacts from the proposals, and with the polish only from r > 0.9
    (E < 100 mm, ``polish.from_r_free: null``: the loop must first come near) the best trial
    lands in fewer iterations."""
    robot, _, _ = shipped
    problems = [gt.random_reachable_problem(robot, FRESH + k) for k in range(12)]
    first, iterations = {}, {}
    base = gt.SolverCfg()
    for start in ("random", "proposal"):
        paper = gt.SolverCfg.paper(start=start, max_iterations=1)
        near = replace(base, start=start, max_iterations=300, polish=replace(base.polish, from_r_free=None))
        f, it = [], []
        for k, problem in enumerate(problems):
            f.append(float(gt.solve(problem, trials=4, seed=k, solver=paper).outcome.history["total"][0].min()))
            result = gt.solve(problem, trials=4, seed=k, solver=near)
            assert result.success
            it.append(result.best.iterations)
        first[start], iterations[start] = np.median(f), np.mean(it)
    assert first["proposal"] < first["random"] / 5
    assert iterations["proposal"] < iterations["random"] / 4


def test_the_loop_evaluates_its_given_start_first(shipped):
    """With a start, iteration 1 is the start itself (the networks placed there learn from the
    second): its recorded error is the environment's error of the start."""
    robot, ik, model = shipped
    problem = gt.random_reachable_problem(robot, FRESH + 50, 4)
    cfg = gt.SolverCfg(polish=gt.PolishCfg(from_r=None), max_iterations=3)
    env = build_environment(robot, problem, ik, cfg)
    starts = proposal_starts(model, env, 6)
    assert bool(starts.given.all())  # nothing to collide with: every trial at its proposal
    outcome = run_loop(env, 6, 0, cfg, start=starts)
    start = starts.config
    span = env.upper - env.lower
    kept = env.lower + span * ((start - env.lower) / span).clamp(START_MARGIN, 1 - START_MARGIN)  # kept inside
    expected = env.evaluate(kept).error
    assert torch.allclose(outcome.history["total"][0], expected.to(outcome.history["total"].dtype), atol=1e-6)
    props = proposals(model, env)  # nothing to collide with: ranked by the model's score, unevaluated
    order = props.score[0].argsort()[:6]
    assert torch.equal(start, props.config[0, order])  # trial j starts at the j-th best proposal
    first, second = outcome.history["total"][0], outcome.history["total"][1]
    assert bool((second < first + 0.1).all())  # placed there, expecting its reinforcement: stays near


def test_hand_proposals_follow_the_contacts_moved_and_turned(shipped):
    """The same contacts moved and turned anywhere: the model sees the same input (its
    environment's search frame is made from the contacts) and its proposals, in the world, move
    and turn with them."""
    from graspnet_torch.robot.transforms import compose, pose_to_matrix, pose_to_rt

    robot, ik, model = shipped
    problem = gt.random_reachable_problem(robot, FRESH + 60, 4)
    rng = np.random.default_rng(0)
    cfg = gt.SolverCfg()
    base = build_environment(robot, problem, ik, cfg)
    t0, m0 = base.proposal_input()
    c0 = model(t0, m0)[0][0].double()
    for _ in range(3):
        M = random_pose(rng)
        env = build_environment(robot, problem.moved(M), ik, cfg)
        t1, m1 = env.proposal_input()
        assert torch.allclose(t1, t0, atol=1e-5) and torch.equal(m1, m0)
        c1 = model(t1, m1)[0][0].double()
        world0 = compose(*base.frame64, *pose_to_rt(c0))
        world1 = compose(*env.frame64, *pose_to_rt(c1))
        moved = torch.as_tensor(M) @ torch.cat([torch.cat([world0[0], world0[1].unsqueeze(-1)], -1),
                                                 torch.tensor([[[0, 0, 0, 1.0]]]).expand(len(c0), 1, 4)], 1)
        assert torch.allclose(world1[0], moved[:, :3, :3], atol=1e-4)
        assert torch.allclose(world1[1], moved[:, :3, 3], atol=1e-4)
    assert pose_to_matrix  # imported for the reader: poses are (x, y, z, rx, ry, rz)


def test_a_checkpoint_is_validated_on_load(shipped, tmp_path):
    robot, _, model = shipped
    path = save_proposal(model, robot, ProposalCfg(heads=model.heads), tmp_path / "hand.posture.pt")
    again = load_proposal(robot, path)
    t = torch.randn(3, model.slots, 3) * 0.05
    m = torch.ones(3, model.slots)
    assert torch.equal(again(t, m)[0], model(t, m)[0])
    with pytest.raises(CheckpointError, match="not for robot 'hand'"):
        load_proposal(robot, posture_checkpoint(gt.load_robot("arm_hand")))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match=r"junk\.pt: not a readable"):
        load_proposal(robot, tmp_path / "junk.pt")
    payload = torch.load(path, weights_only=True)
    payload["state"]["out.bias"][0] = float("nan")
    torch.save(payload, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match="non-finite"):
        load_proposal(robot, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match="no posture proposal model"):
        load_proposal(robot, tmp_path / "missing.pt")


def test_a_robot_without_a_model_starts_at_random_and_says_so_once(tmp_path):
    """A hand by config with no posture checkpoint beside it: solver.start=proposal warns once
    and gives exactly the random start's result."""
    import yaml

    from graspnet_torch.paths import repo_root

    data = yaml.safe_load((repo_root() / "configs" / "robot" / "hand.yaml").read_text())
    data["name"] = "hand_copy"
    data["urdf"] = str((repo_root() / data["urdf"]).resolve())
    data["checkpoint"] = str((repo_root() / "checkpoints" / "hand" / "fcnn.pt").resolve())
    path = tmp_path / "hand_copy.yaml"
    path.write_text(yaml.safe_dump(data))
    robot, ik = api.robot_and_ik(str(path))
    problem = gt.random_reachable_problem(robot, FRESH + 70, 3)
    solver = replace(gt.SolverCfg(), start="proposal")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = gt.solve(problem, trials=4, seed=1, solver=solver, robot=robot, finger_ik=ik)
        gt.solve(problem, trials=4, seed=1, solver=solver, robot=robot, finger_ik=ik)
    said = [str(w.message) for w in caught if "posture proposal" in str(w.message)]
    assert len(said) == 1 and "hand_copy" in said[0] and "train_posture.py" in said[0]
    b = gt.solve(problem, trials=4, seed=1, robot=robot, finger_ik=ik)
    assert [t.to_dict() | {"wall_time_s": 0} for t in a.trials] == [t.to_dict() | {"wall_time_s": 0} for t in b.trials]


@pytest.mark.parametrize("name", ["arm_hand", "manus"])
def test_arm_and_gripper_proposals_beat_random_configurations(name):
    """Best of K proposals on fresh problems against the best of K uniform random configurations
    (an arm's fingers by the FCNN, a gripper's settling steps; no iteration)."""
    robot, ik = api.robot_and_ik(name)
    table = evaluate_proposal(proposal_of(robot), robot, ik, n=30, seed=FRESH)
    assert table["median_mm"] < table["random_median_mm"] / 3


def test_solve_many_starts_every_problem_at_its_own_proposals(shipped):
    """A batch: each problem's trials start at that problem's best proposals (recomputed one
    problem at a time), and every problem lands with two trials."""
    robot, ik, model = shipped
    problems = [gt.random_reachable_problem(robot, FRESH + 80 + k) for k in range(4)]
    cfg = gt.SolverCfg()
    batch = build_environment(robot, problems, ik, cfg, runs=2)
    starts = proposal_starts(model, batch, 8)
    for k, p in enumerate(problems):
        alone = proposal_starts(model, build_environment(robot, p, ik, cfg), 2)
        assert torch.allclose(starts.config[2 * k: 2 * k + 2], alone.config, atol=1e-5)
    results = gt.solve_many(problems, trials=2, solver=replace(cfg, start="proposal"))
    assert all(r.success and r.best.total_error_mm < 1 for r in results)
    assert math.isfinite(sum(r.best.total_error_mm for r in results))


@pytest.mark.slow
def test_the_arm_from_proposals_among_unknown_obstacles():
    """The arm's proposals do not see env2's obstacles and object: a finger of their polished grasps
    passes through the object where the proxy misses it. Each such grasp is refused by FCL in the
    loop, and the search goes on: collision-free grasps on 3 seeds, in fewer iterations than
    from random starts (the sum over the seeds)."""
    its = {}
    for start in ("proposal", "random"):
        its[start] = 0
        for seed in range(1000, 1003):
            r = gt.solve("env2", trials=16, seed=seed, solver=gt.SolverCfg(start=start))
            assert r.success and r.best.collisions == 0 and r.best.total_error_mm < 1
            its[start] += r.best.iterations
    assert its["proposal"] < its["random"]


def test_colliding_proposals_start_at_random_for_independent_learners():
    """Where every trial runs to its own stop, a proposal the environment finds colliding (the
    MANUS through the cube's table) starts its trial at random; where the trials are restarts
    of one search they start there."""
    from graspnet_torch.tasks.manus import cube_problem, protocol_positions

    robot = gt.load_robot("manus")
    model = proposal_of(robot)
    env = build_environment(robot, cube_problem(*protocol_positions()[5]), None, gt.SolverCfg(),
                            reward=gt.RewardCfg(kind="r3", a=1.0, p=50))
    starts = proposal_starts(model, env, 10, colliding_random=True)
    clear = int((env.evaluate(proposals(model, env).config[0]).collisions == 0).sum())
    assert 0 < clear < 10  # some of the ten best collide
    assert starts.given.tolist() == [True] * clear + [False] * (10 - clear)  # colliding ones rank last
    assert bool(proposal_starts(model, env, 10, colliding_random=False).given.all())
