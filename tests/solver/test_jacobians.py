"""Every analytic Jacobian of the least-squares model against forward differences
(:func:`~graspnet_torch.least_squares.numerical_jacobian`): the palm pose's frame (small
angles included), the whole hand x = [palm pose, fingers], the arm + hand x = [arm joints,
fingers], a hand with mimic joints, prismatic joints and padded fingers, the gripper's points;
and Levenberg-Marquardt with them converges on random reachable problems."""

from __future__ import annotations

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.fcnn import FingerIK, load_finger_ik
from graspnet_torch.fcnn.experts import ExpertSet
from graspnet_torch.least_squares import numerical_jacobian
from graspnet_torch.robot.transforms import frame_point_jacobian, pose_jacobian, pose_to_rt, transform_points
from graspnet_torch.solver import SolverCfg
from graspnet_torch.solver.api import build_environment
from tests.odd_hands import write_oddhand

H = 1e-7  # forward differences in float64: truncation ~h |f''|, rounding ~1e-16 / h


def close_to_differences(f, x: torch.Tensor, J: torch.Tensor, h: float = H, tol: float = 2e-6) -> None:
    """J (B, k, m) against forward differences of the value function f: x (b, m) -> (b, k)."""
    fd = numerical_jacobian(f, x, h)
    assert J.shape == fd.shape
    assert (J - fd).abs().max() < tol * max(1.0, float(fd.abs().max()))


def repeat_rows(rows: torch.Tensor, m: int) -> torch.Tensor:
    """The rows of numerical_jacobian's (b (m + 1), m) batch: each row m + 1 times."""
    return rows.repeat_interleave(m + 1)


def test_pose_frame_jacobian_is_exact_at_random_and_small_angles():
    g = torch.Generator().manual_seed(0)
    pose = (torch.rand(64, 6, generator=g, dtype=torch.float64) - 0.5) * 6
    pose[:16, 3:] *= 1e-7  # near the identity
    pose[16:24, 4] = torch.pi / 2 - 1e-3  # near gimbal lock: the derivative stays exact
    y = torch.randn(64, 5, 3, generator=g, dtype=torch.float64)
    R, t, Jc = pose_jacobian(pose)
    R0, t0 = pose_to_rt(pose)
    assert torch.equal(R, R0) and torch.equal(t, t0)
    J = frame_point_jacobian(R, Jc, y).reshape(64, 15, 6)

    def points(x):
        Rx, tx = pose_to_rt(x)
        yy = y.repeat_interleave(7, 0)
        return transform_points(Rx.unsqueeze(-3), tx.unsqueeze(-2), yy).reshape(-1, 15)

    close_to_differences(points, pose, J)


def whole_model_check(env, seed: int = 0, B: int = 12) -> None:
    gen = torch.Generator().manual_seed(seed)
    x = env.random_whole(B, gen)
    rows = torch.arange(B)
    tips, J = env.whole_tips(x, rows)
    m = x.shape[1]
    assert tips.shape == (B, 3 * len(env.fingers)) and J.shape == (B, tips.shape[1], m)
    close_to_differences(lambda xx: env.whole_tips(xx, repeat_rows(rows, m))[0], x, J)


def test_free_hand_whole_jacobian(hand):
    problem = gt.random_reachable_problem(hand, 3)
    env = build_environment(hand, problem, load_finger_ik(hand), SolverCfg())
    whole_model_check(env)


def test_masked_fingers_of_a_batch_have_zero_rows(hand):
    problems = [gt.random_reachable_problem(hand, s) for s in (1, 2, 5)]
    env = build_environment(hand, problems, load_finger_ik(hand), SolverCfg(), runs=2)
    whole_model_check(env, B=6)
    x = env.random_whole(6, torch.Generator().manual_seed(1))
    tips, J = env.whole_tips(x, torch.arange(6))
    off = (env.mask.cpu() == 0).repeat_interleave(3, 1)  # (T, 3F)
    assert bool(off.any()) and bool((tips[off] == 0).all()) and bool((J[off] == 0).all())


def test_arm_hand_whole_jacobian():
    robot = gt.load_robot("arm_hand")
    q = torch.as_tensor(sum(robot.body_limits) / 2)
    tips = robot.fingertips_world_from_body(q, robot.home_posture().fingers)
    problem = gt.GraspProblem.from_mapping({"robot": "arm_hand", "contacts": [
        {"finger": f, "position": tips[robot.finger_index(f)].tolist()} for f in ("thumb", "index", "ring")]},
        source="arm")
    env = build_environment(robot, problem, load_finger_ik(robot), SolverCfg())
    whole_model_check(env)


def test_mimic_prismatic_and_padded_fingers_whole_jacobian(tmp_path):
    robot = gt.load_robot(str(write_oddhand(tmp_path)))
    experts = {}
    for name in robot.finger_names:
        lo, hi = (torch.as_tensor(a[robot.finger_index(name)]) for a in robot.finger_limits)
        experts[name] = ExpertSet(robot.fingers[name].n_joints, torch.zeros(3), torch.ones(3),
                                  lo[: robot.fingers[name].n_joints], hi[: robot.fingers[name].n_joints])
    ik = FingerIK(robot, experts)  # untrained: the Jacobian needs none of it
    zero = robot.fingertips_world(torch.zeros(6, dtype=torch.float64), robot.home_posture().fingers)
    problem = gt.GraspProblem.from_mapping({"robot": "oddhand", "contacts": [
        {"finger": f, "position": zero[robot.finger_index(f)].tolist()} for f in robot.finger_names]},
        source="odd", robot_cfg=robot.cfg)
    env = build_environment(robot, problem, ik, SolverCfg())
    assert len(env.fingers) == 4 and robot.joints_per_finger == 4
    whole_model_check(env)


def test_gripper_points_jacobian():
    robot = gt.load_robot("manus")
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    q = lo + (hi - lo) * torch.rand(10, lo.shape[0], generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    p, J = robot.gripper_points_jacobian(q)
    assert torch.equal(p, robot.gripper_points(q))
    close_to_differences(lambda x: robot.gripper_points(x).reshape(-1, 6), q, J.reshape(10, 6, -1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_levenberg_marquardt_lands_on_random_reachable_hand_problems(hand, seed):
    """From random starts within the bounds (solver=dls's restarts), the analytic model takes
    rows of each problem below 1 micron, within the bounds, and the reported error is the model's."""
    problem = gt.random_reachable_problem(hand, seed)
    env = build_environment(hand, problem, load_finger_ik(hand), SolverCfg())
    x = env.random_whole(32, torch.Generator().manual_seed(seed))
    solved = env.local_solve(x, 100, tol=1e-6)
    lo, hi = env.whole_bounds()
    assert bool(((solved.x >= lo) & (solved.x <= hi)).all())
    assert int((solved.err < 1e-6).sum()) >= 4
    tips, _ = env.whole_tips(solved.x)
    assert torch.allclose(tips, solved.value, rtol=0, atol=1e-12)
