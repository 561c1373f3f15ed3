"""gt.Solver: built once, the same answers as gt.solve; warm starts and tracking stay near the
previous posture and land; a frame the warm start cannot land gets the full search."""

from __future__ import annotations

import itertools
import math

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.solver.postures import trial_posture


@pytest.fixture(scope="module")
def hand_solver():
    return gt.Solver("hand", trials=8)


def _frames(robot: gt.Robot, n: int, seed: int = 0) -> list[gt.GraspProblem]:
    """A smooth walk of a random posture (about 2 mm / 2 degrees per frame), four contact fingers."""
    g = torch.Generator().manual_seed(seed)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    plo, phi = torch.as_tensor(robot.palm_bounds.lower), torch.as_tensor(robot.palm_bounds.upper)
    pose = (plo + phi) / 2
    q = lo + (hi - lo) * (0.3 + 0.4 * torch.rand(lo.shape, generator=g, dtype=torch.float64))
    out = []
    for _ in range(n):
        step = torch.randn(6, generator=g, dtype=torch.float64) * torch.tensor([0.002] * 3 + [0.02] * 3)
        pose = torch.clamp(pose + step, plo, phi)
        q = torch.clamp(q + 0.02 * torch.randn(q.shape, generator=g, dtype=torch.float64), lo, hi)
        tips = robot.fingertips_world(pose, q)
        out.append(gt.GraspProblem.from_mapping({"robot": robot.name, "contacts": [
            {"finger": f, "position": tips[i].tolist()} for i, f in enumerate(robot.finger_names[:4])]}))
    return out


def test_a_built_solver_gives_what_gt_solve_gives(hand_solver):
    problem = gt.random_reachable_problem(hand_solver.robot, 7)
    ours = hand_solver.solve(problem, seed=3)
    theirs = gt.solve(problem, trials=8, seed=3)
    assert [t.to_dict() | {"wall_time_s": 0} for t in ours.trials] == \
        [t.to_dict() | {"wall_time_s": 0} for t in theirs.trials]


def test_tracking_lands_every_frame_warm_and_without_jumps(hand_solver):
    robot = hand_solver.robot
    frames = _frames(robot, 25)
    results = hand_solver.track(frames)
    assert all(r.success and r.best.total_error_mm < 1 for r in results)
    warm = sum(len(r.trials) == 1 for r in results[1:])
    assert warm >= 22  # the warm start lands (one trial) on nearly every frame after the first
    for a, b in itertools.pairwise(results):
        qa, qb = (trial_posture(robot, r.best).fingers for r in (a, b))
        assert float((qa - qb).abs().max()) < math.radians(20)
    for problem, r in zip(frames, results, strict=True):  # independently: forward kinematics of what it reports
        posture = trial_posture(robot, r.best)
        tips = robot.fingertips_world(posture.palm_pose, posture.fingers)
        for c in problem.contacts:
            err = float(torch.linalg.vector_norm(tips[robot.finger_index(c.finger)] - torch.as_tensor(c.position)))
            assert err * 1000 == pytest.approx(r.best.fingertip_error_mm[c.finger], abs=1e-6)


def test_a_warm_start_that_cannot_land_falls_back_to_the_search_and_reports_the_nearest(hand_solver):
    """Two polish steps cannot bring a far posture onto a new frame: the search runs, the warm
    trial is listed first, and the reported trial is, of the successful ones, the one whose joints
    moved least from the start (recomputed here; no centring, ``polish.centre: null``)."""
    import dataclasses

    robot = hand_solver.robot
    cfg = hand_solver.solver_cfg
    short = gt.Solver(robot, trials=8, solver=dataclasses.replace(cfg, polish=dataclasses.replace(
        cfg.polish, iterations=2, centre=None)))
    far = hand_solver.solve(gt.random_reachable_problem(robot, 1, 4))
    result = short.solve(gt.random_reachable_problem(robot, 4, 5), start=far)
    assert result.success and len(result.trials) == 1 + short.trials and not result.trials[0].success
    start = trial_posture(robot, far.best)
    moved = {k: float((trial_posture(robot, t).fingers - start.fingers).abs().max())
             for k, t in enumerate(result.trials) if t.success and t.collisions == 0}
    assert result.chosen == min(moved, key=moved.get) and result.best is result.trials[result.chosen]


def test_a_warm_start_from_its_own_answer_lands_at_once(hand_solver):
    problem = gt.random_reachable_problem(hand_solver.robot, 2, 5)
    result = hand_solver.solve(problem)
    near = hand_solver.solve(problem, start=result)  # from its own answer: lands at once, one trial
    assert near.success and len(near.trials) == 1 and near.best.total_error_mm <= result.best.total_error_mm + 1e-6


def test_a_problem_of_another_robot_is_refused(hand_solver):
    with pytest.raises(gt.ProblemError, match="this solver's is 'hand'"):
        hand_solver.solve("cube")


@pytest.mark.parametrize("name", ["arm_hand", "manus"])
def test_every_kind_of_robot_warm_starts_from_its_own_answer(name):
    """The contract's whole_of for an arm (its joints) and a gripper (its body): a warm start
    from a result lands at once, one trial, no worse."""
    solver = gt.Solver(name, trials=8)
    problem = gt.GraspProblem.from_task("env1" if name == "arm_hand" else "cube")
    first = solver.solve(problem)
    again = solver.solve(problem, start=first)
    assert first.success and again.success and len(again.trials) == 1
    assert again.best.error_mm <= first.best.error_mm + 1e-6


def test_solve_many_of_a_solver_built_from_a_robot_uses_that_robot_and_fcnn(hand_solver):
    """A Solver given a Robot and an FCNN hands both to the batch: the same results as
    gt.solve_many given them explicitly."""
    problems = [gt.random_reachable_problem(hand_solver.robot, 900 + k) for k in range(3)]
    solver = gt.Solver(hand_solver.robot, trials=4, finger_ik=hand_solver.finger_ik)
    ours = solver.solve_many(problems)
    theirs = gt.solve_many(problems, trials=4, robot=hand_solver.robot, finger_ik=hand_solver.finger_ik)
    assert [[t.to_dict() | {"wall_time_s": 0} for t in r.trials] for r in ours] == \
        [[t.to_dict() | {"wall_time_s": 0} for t in r.trials] for r in theirs]


def _spread(robot: gt.Robot, posture, fingers) -> float:
    """The mean distance of the contact fingers' joints from the middle of their ranges, in ranges."""
    idx = [robot.finger_index(f) for f in fingers]
    lo, hi = (torch.as_tensor(a)[idx] for a in robot.finger_limits)
    span = hi - lo
    u = (posture.fingers[idx] - lo) / span.clamp_min(1e-12)
    return float((u - 0.5).abs()[span > 0].mean())


def test_a_searched_frame_of_a_sequence_is_centred_contacts_held(hand_solver):
    """The first frame of a track is searched, then moved toward the middle of its joint ranges
    with the contacts held (polish.centre): reported as an added last trial that is still a
    grasp, its joints nearer the middle than the search's (recomputed here), none moved more
    than polish.warm_step_deg."""
    robot = hand_solver.robot
    problem = gt.random_reachable_problem(robot, 11, 4)
    searched = hand_solver.solve(problem)
    first = hand_solver.track([problem])[0]
    assert first.chosen == len(first.trials) - 1 == len(searched.trials)
    assert first.success and first.best.total_error_mm < 1
    before, after = trial_posture(robot, searched.best), trial_posture(robot, first.best)
    assert _spread(robot, after, problem.fingers) < _spread(robot, before, problem.fingers)
    step = math.radians(hand_solver.solver_cfg.polish.warm_step_deg)
    assert float((after.fingers - before.fingers).abs().max()) <= step + 1e-6  # float32 results: ~1e-8 rad


def test_a_warm_start_moves_no_finger_joint_more_than_its_step(hand_solver):
    """From a solution with every finger joint moved 30 degrees toward the middle of its range,
    the warm start's own trial moves no finger joint more than polish.warm_step_deg (5); with the
    step unbounded (null) it moves them back further."""
    import dataclasses

    robot = hand_solver.robot
    problem = gt.random_reachable_problem(robot, 21, 4)
    start = trial_posture(robot, hand_solver.solve(problem).best)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    toward = torch.sign((lo + hi) / 2 - start.fingers) * math.radians(30)
    moved = gt.Posture(palm_pose=start.palm_pose, fingers=torch.clamp(start.fingers + toward, lo, hi), body=start.body)
    cfg = hand_solver.solver_cfg
    for step in (5.0, None):
        solver = gt.Solver(robot, trials=8, solver=dataclasses.replace(cfg, polish=dataclasses.replace(
            cfg.polish, warm_step_deg=step, centre=None)))
        warm = solver.solve(problem, start=moved).trials[0]
        idx = [robot.finger_index(f) for f in problem.fingers]  # the other fingers are reported at home
        change = math.degrees(float((trial_posture(robot, warm).fingers - moved.fingers)[idx].abs().max()))
        if step is not None:
            assert change <= step + 1e-4  # results pass through float32: ~1e-6 degrees
        else:
            unbounded = change
    assert unbounded > 5.0
