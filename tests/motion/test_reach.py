"""Reach motions: planned around what the straight line hits, timed within the limits, and
re-checked independently (a re-check that can fail: a motion made to cut through, or run too
fast, is caught)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.motion import MotionChecker, StateLayout, check_motion, start_posture, time_path
from graspnet_torch.solver.postures import trial_posture


@pytest.fixture(scope="module")
def env2():
    problem = gt.GraspProblem.from_task("env2")
    result = gt.solve(problem, trials=16, seed=0)
    assert result.success
    return gt.load_robot("arm_hand"), problem, result


def test_time_path_stays_on_its_segments_within_the_limits():
    """Rest to rest through three corners: every row on the polyline, the corners hit, the
    velocities and accelerations (finite differences) within the limits, each joint's
    velocity limit reached on the long segment by the joint that must move farthest."""
    corners = np.array([[0.0, 0.0], [1.0, 0.5], [1.0, -0.5]])
    velocity, acceleration = np.array([0.5, 2.0]), np.array([4.0, 4.0])
    t, x, at = time_path(corners, velocity, acceleration, 100.0)
    assert at == [0, at[1], len(t) - 1] and np.allclose(x[at], corners)
    for a, b, lo, hi in ((corners[0], corners[1], at[0], at[1]), (corners[1], corners[2], at[1], at[2])):
        d = b - a
        s = (x[lo: hi + 1] - a) @ d / (d @ d)
        assert np.allclose(a + s[:, None] * d, x[lo: hi + 1], atol=1e-9) and np.all(np.diff(s) >= -1e-12)
    v = np.diff(x, axis=0) / np.diff(t)[:, None]
    assert np.all(np.abs(v) <= velocity * (1 + 1e-6))
    assert np.max(np.abs(v[: at[1], 0])) > 0.49  # x moves 1 rad: it cruises at its limit
    dt = np.diff(t)
    acc = 2 * (v[1:] - v[:-1]) / (dt[1:] + dt[:-1])[:, None]
    assert np.all(np.abs(acc) <= acceleration * (1 + 1e-6))


@pytest.mark.slow
def test_the_motion_goes_around_what_the_straight_line_hits(env2):
    """env2's grasp from the home posture: the straight line in joint space (the arm to the grasp,
    fingers as at the start) runs into an obstacle; the planned motion avoids it: FCL finds
    nothing along it, it starts at the start and ends at the reported grasp, it detours (more
    than the two ends), and it keeps within the joint, velocity and acceleration limits."""
    robot, problem, result = env2
    checker = MotionChecker(robot, problem, StateLayout.of(robot))
    start = checker.state(start_posture(robot, problem))
    goal = checker.state(trial_posture(robot, result.best))
    straight = goal.copy()
    straight[7:] = start[7:]
    assert checker.first_collision(start, straight, 0.5, 1.0) is not None  # the straight line collides
    motion = gt.plan_reach(problem, result)
    assert motion.found, motion.reason
    assert check_motion(robot, problem, result.best, motion) == []
    assert np.allclose(motion.positions[0], start, atol=1e-9) and np.allclose(motion.positions[-1], goal, atol=1e-9)
    body = motion.positions[:, :7]
    line = goal[:7] - start[:7]
    s = (body - start[:7]) @ line / (line @ line)
    assert np.max(np.linalg.norm(body - (start[:7] + s[:, None] * line), axis=1)) > math.radians(5)  # it detours


@pytest.mark.slow
def test_the_re_check_catches_a_motion_through_an_obstacle_or_too_fast(env2):
    """The same motion's rows replaced by the straight line (timed alike): FCL finds the collision;
    the motion played twice as fast: the velocity limit is exceeded."""
    robot, problem, result = env2
    motion = gt.plan_reach(problem, result)
    assert motion.found
    s = np.linspace(0.0, 1.0, len(motion.times))[:, None]
    through = replace(motion, positions=motion.positions[0] + s * (motion.positions[-1] - motion.positions[0]))
    assert any("FCL finds a collision" in m for m in check_motion(robot, problem, result.best, through))
    fast = replace(motion, times=motion.times / 2)
    assert any("velocity exceeds" in m for m in check_motion(robot, problem, result.best, fast))


@pytest.mark.slow
def test_the_manus_reaches_the_cube_from_home_with_its_jaws_touching_only_at_the_end():
    problem = gt.GraspProblem.from_task("cube")
    result = gt.solve(problem, trials=8, seed=0)
    robot = gt.load_robot("manus")
    motion = gt.plan_reach(problem, result)
    assert motion.found, motion.reason
    assert check_motion(robot, problem, result.best, motion) == []
    checker = MotionChecker(robot, problem, StateLayout.of(robot))
    arrived = checker.arrived(motion.positions)
    assert arrived[-1] and not arrived[0] and np.all(np.diff(arrived.astype(int)) >= 0)  # touching: the end only


def test_a_free_hand_approaches_from_its_pre_grasp():
    """A free hand has no start: its motion is the approach, from the palm backed off by
    reach.backoff_m (fingers open) to the grasp, then the fingers close."""
    problem = gt.GraspProblem.from_task("block5")
    result = gt.solve(problem, trials=16, seed=0)
    robot = gt.load_robot("hand")
    motion = gt.plan_reach(problem, result, gt.ReachCfg(backoff_m=0.08))
    assert motion.found, motion.reason
    assert motion.joint_names[:6] == ["palm_x", "palm_y", "palm_z", "palm_rx", "palm_ry", "palm_rz"]
    assert np.linalg.norm(motion.positions[0, :3] - motion.positions[-1, :3]) == pytest.approx(0.08)
    assert check_motion(robot, problem, result.best, motion) == []


@pytest.mark.slow
def test_reach_true_adds_the_motion_to_the_result_and_a_gif(tmp_path):
    """solve_grasp.py task=env1 reach=true: the result's trajectory (URDF names, degrees, times from
    0) starts at the problem's start and ends at the reported arm and finger joints; reach.gif."""
    from graspnet_torch.jobs import solve_grasp as job

    out = tmp_path / "r.json"
    problem = tmp_path / "p.yaml"
    import yaml

    from graspnet_torch.paths import configs_dir

    data = yaml.safe_load((configs_dir() / "task" / "env1.yaml").read_text())
    data["start"] = {"shoulder_abduction": 10, "elbow_flexion": 20}
    problem.write_text(yaml.safe_dump(data))
    job.solve_grasp({"problem": str(problem), "trials": 16, "out": str(out), "tensorboard": False, "pictures": True,
                     "reach": True}, tmp_path / "run")
    result = json.loads(out.read_text())
    motion = result["trajectory"]
    assert motion["found"] and motion["reason"] == "" and motion["planner"] == "RRTConnect"
    names = motion["joint_names"]
    first = dict(zip(names, motion["positions"][0], strict=True))
    last = dict(zip(names, motion["positions"][-1], strict=True))
    assert first["shoulder_abduction"] == pytest.approx(10) and first["elbow_flexion"] == pytest.approx(20)
    assert first["shoulder_flexion"] == 0
    for joint, value in result["arm_joints"].items():
        assert last[joint] == pytest.approx(value, abs=1e-6)
    for finger, values in result["joints"].items():
        chain = gt.load_robot("arm_hand").fingers[finger].chain
        for name, v in zip(chain.all_joint_names, values, strict=True):
            if name in last:
                assert last[name] == pytest.approx(v, abs=1e-6)
    assert motion["times"][0] == 0 and np.all(np.diff(motion["times"]) > 0)
    assert (tmp_path / "run" / "reach.gif").read_bytes()[:6] in (b"GIF89a", b"GIF87a")


def test_a_trajectory_reads_back_what_it_writes():
    """to_dict (degrees for the angles) and from_dict are inverses."""
    motion = gt.Trajectory(["a", "b"], np.array([0.0, 0.5]), np.array([[0.1, 0.2], [0.3, -0.4]]),
                           np.array([True, False]), "RRTConnect", 0.25)
    data = motion.to_dict()
    assert data["positions"][1] == [pytest.approx(math.degrees(0.3)), -0.4]
    back = gt.Trajectory.from_dict(json.loads(json.dumps(data)), np.array([True, False]))
    assert np.allclose(back.positions, motion.positions) and np.allclose(back.times, motion.times)
    assert (back.found, back.reason, back.planner) == (True, "", "RRTConnect")


def test_a_distal_link_may_touch_the_object_only_while_its_fingertip_is_near_its_contact():
    """At env2's grasp in the point model the contact fingers' distal links reach into the object
    (as that model allows); the checker takes that state as clear, but not with the object moved so
    that every contact lies farther than reach.touch_mm from its fingertip while the links still
    cross it."""
    robot, problem = gt.load_robot("arm_hand"), gt.GraspProblem.from_task("env2")
    result = gt.solve(problem, trials=16, seed=0, solver={"contact_model": "point"})
    layout = StateLayout.of(robot)
    goal = MotionChecker(robot, problem, layout).state(trial_posture(robot, result.best))
    checker = MotionChecker(robot, problem, layout, touch_mm=40.0)
    assert checker.arrived_fingers(goal[None]).all() and checker.clear(goal[None])[0]
    assert not checker.strictly_clear(goal[None])[0]  # the links do touch the object
    strict = MotionChecker(robot, problem, layout, touch_mm=0.0)  # no fingertip is ever near enough
    assert not strict.clear(goal[None])[0]


@pytest.mark.slow
def test_the_fingers_open_clear_of_the_object_before_the_arm_moves(env2):
    """The motion's second corner (the fingers open at the start) carries the opening its arm
    brings to the grasp: there, no link touches the object."""
    robot, problem, result = env2
    motion = gt.plan_reach(problem, result)
    assert motion.found, motion.reason
    checker = MotionChecker(robot, problem, StateLayout.of(robot))
    goal = checker.state(trial_posture(robot, result.best))
    opened = goal.copy()
    moving = np.nonzero(np.any(np.abs(np.diff(motion.positions[:, :7], axis=0)) > 0, axis=1))[0]
    opened[7:] = motion.positions[moving[0], 7:]  # the fingers when the arm starts moving
    assert not np.allclose(opened[7:], goal[7:])
    assert checker.strictly_clear(opened[None])[0]


@pytest.mark.slow
def test_a_surface_grasp_is_reached_through_its_own_pre_grasp():
    """The surface contact model's result carries a pre-grasp (the pads backed off along the
    object's normals): the motion passes through it, the palm where the grasp has it, then closes
    onto the grasp; FCL finds nothing along it."""
    problem = gt.GraspProblem.from_task("glass3")
    result = gt.solve(problem, trials=8, seed=0, solver={"contact_model": "surface", "normal_cone_deg": 90.0})
    assert result.success and result.best.pregrasp is not None
    robot = gt.load_robot("hand")
    motion = gt.plan_reach(problem, result)
    assert motion.found, motion.reason
    checker = MotionChecker(robot, problem, StateLayout.of(robot))
    goal = checker.state(trial_posture(robot, result.best))
    pre = checker.state(trial_posture(robot, result.best.pregrasp))
    pre[:6] = goal[:6]
    assert np.abs(motion.positions - pre).max(1).min() < 1e-9  # a row is the pre-grasp
    np.testing.assert_allclose(motion.positions[-1], goal, atol=1e-9)
    assert check_motion(robot, problem, result.best, motion) == []
