"""Robot: DOF counts, whole-robot kinematics against pytorch-kinematics, frames, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.robot.transforms import pose_to_matrix
from tests.conftest import uniform


def test_dof_counts(robots):
    hand, arm_hand, manus = robots["hand"], robots["arm_hand"], robots["manus"]
    assert (hand.n_finger_joints, hand.dof) == (20, 26)
    assert (arm_hand.n_finger_joints, len(arm_hand.body_joint_names), arm_hand.dof) == (20, 7, 27)
    assert len(arm_hand.urdf.movable_joint_names) == 27
    assert (manus.n_fingers, len(manus.body_joint_names), manus.dof) == (0, 9, 9)
    assert hand.finger_names == ("thumb", "index", "middle", "ring", "pinky")
    assert hand.joints_per_finger == 4


def test_finger_joint_order_is_abduction_then_flexions(hand):
    assert hand.fingers["index"].joint_names == ("index_abd", "index_mcp", "index_pip", "index_dip")
    assert hand.fingers["thumb"].joint_names == ("thumb_cmc_abd", "thumb_cmc_flex", "thumb_mcp", "thumb_ip")


def _pk_tree_points(robot, th_by_name, links):
    chain = robot.urdf.chain.to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    th = torch.stack([th_by_name[n] for n in names], dim=-1)
    frames = chain.forward_kinematics(th)
    return torch.stack([frames[link].get_matrix()[:, :3, 3] for link in links], dim=1)


def test_hand_fingertips_world_match_pytorch_kinematics_tree(hand, gen):
    n = 300
    lo, hi = hand.finger_limits
    q = uniform(lo, hi, n, gen)
    b = hand.palm_bounds
    pose = uniform(b.lower, b.upper, n, gen)
    th = {name: q[:, k, j] for k, f in enumerate(hand.fingers.values()) for j, name in enumerate(f.joint_names)}
    tips_palm = _pk_tree_points(hand, th, [c.tip for c in hand.cfg.fingers.values()])
    T = pose_to_matrix(pose)
    expected = (T[:, None, :3, :3] @ tips_palm.unsqueeze(-1)).squeeze(-1) + T[:, None, :3, 3]
    assert (hand.fingertips_world(pose, q) - expected).abs().max() < 1e-6
    assert (hand.fingertips_palm(q) - tips_palm).abs().max() < 1e-6


@pytest.mark.parametrize("rows", [[0], [0, 2, 3], [4, 1]])
def test_some_fingertips_are_those_rows_of_every_fingertip_bit_for_bit(hand, gen, rows):
    n = 257
    lo, hi = hand.finger_limits
    q = uniform(lo, hi, n, gen)
    b = hand.palm_bounds
    pose = uniform(b.lower, b.upper, n, gen)
    assert torch.equal(hand.some_fingertips_world(pose, q, rows), hand.fingertips_world(pose, q)[:, rows])
    assert torch.equal(hand.some_fingertips_palm(q, rows), hand.fingertips_palm(q)[:, rows])
    with pytest.raises(ValueError, match="finger joints must have shape"):
        hand.some_fingertips_world(pose, q[:, :2], rows)


def test_arm_hand_fingertips_match_pytorch_kinematics_tree(robots, gen):
    robot = robots["arm_hand"]
    n = 300
    qb = uniform(*robot.body_limits, n, gen)
    q = uniform(*robot.finger_limits, n, gen)
    th = dict(zip(robot.body_joint_names, qb.unbind(-1), strict=True))
    th.update({name: q[:, k, j] for k, f in enumerate(robot.fingers.values()) for j, name in enumerate(f.joint_names)})
    expected = _pk_tree_points(robot, th, [c.tip for c in robot.cfg.fingers.values()])
    assert (robot.fingertips_world_from_body(qb, q) - expected).abs().max() < 1e-6
    palm = _pk_tree_points(robot, th, ["palm"])[:, 0]
    assert (robot.palm_frame(qb)[1] - palm).abs().max() < 1e-6


def test_manus_gripper_points_match_pytorch_kinematics_tree(robots, gen):
    robot = robots["manus"]
    qb = uniform(*robot.body_limits, 300, gen)
    th = dict(zip(robot.body_joint_names, qb.unbind(-1), strict=True))
    expected = _pk_tree_points(robot, th, list(robot.cfg.gripper_points))
    got = robot.gripper_points(qb)
    assert got.shape == (300, 2, 3)
    assert (got - expected).abs().max() < 1e-6
    gap = torch.linalg.norm(got[:, 0] - got[:, 1], dim=-1)
    assert torch.allclose(gap, torch.full_like(gap, 0.07), atol=1e-9)  # rigid jaws, 70 mm apart


def test_contacts_object_to_finger_bases_round_trip(hand, gen):
    """world -> finger base frames is the inverse of fingertip FK placement: contacts taken at
    the fingertips of a posture land exactly on each finger's FK in its base frame."""
    q = uniform(*hand.finger_limits, 50, gen)
    pose = uniform(hand.palm_bounds.lower, hand.palm_bounds.upper, 50, gen)
    world = hand.fingertips_world(pose, q)
    assert (hand.world_to_bases(world, pose) - hand.fingertips_base(q)).abs().max() < 1e-12
    assert (hand.palm_to_base(hand.base_to_palm(world)) - world).abs().max() < 1e-12


def test_arm_contacts_to_finger_bases_round_trip(robots, gen):
    robot = robots["arm_hand"]
    qb = uniform(*robot.body_limits, 40, gen)
    q = uniform(*robot.finger_limits, 40, gen)
    world = robot.fingertips_world_from_body(qb, q)
    assert (robot.world_to_bases_from_body(world, qb) - robot.fingertips_base(q)).abs().max() < 1e-12


def test_link_frames_agree_with_kernel(robots):
    for robot in robots.values():
        home = robot.home_posture()
        frames = robot.link_frames(home)
        if robot.fingers:
            tips = (robot.fingertips_world_from_body(home.body, home.fingers) if robot.has_body
                    else robot.fingertips_world(home.palm_pose, home.fingers))
            for k, c in enumerate(robot.cfg.fingers.values()):
                np.testing.assert_allclose(frames[c.tip][:3, 3], tips[k].numpy(), atol=1e-6)
        if robot.cfg.gripper_points:
            pts = robot.gripper_points(home.body)
            for k, link in enumerate(robot.cfg.gripper_points):
                np.testing.assert_allclose(frames[link][:3, 3], pts[k].numpy(), atol=1e-6)


def test_home_postures_within_limits(robots):
    for robot in robots.values():
        home = robot.home_posture()
        if robot.fingers:
            lo, hi = robot.finger_limits
            assert (home.fingers.numpy() >= lo).all() and (home.fingers.numpy() <= hi).all()
        lo, hi = robot.body_limits
        assert (home.body.numpy() >= lo).all() and (home.body.numpy() <= hi).all()


@pytest.mark.parametrize("shape", [(10, 4), (10, 5, 3), (5,), (10, 4, 4)])
def test_wrong_finger_joint_shape(hand, shape):
    with pytest.raises(ValueError, match=r"finger joints must have shape \(\.\.\., 5, 4\).*thumb, index"):
        hand.fingertips_palm(torch.zeros(shape))


def test_wrong_pose_and_body_shapes(robots):
    hand, arm = robots["hand"], robots["arm_hand"]
    with pytest.raises(ValueError, match=r"palm pose must have shape \(\.\.\., 6\)"):
        hand.fingertips_world(torch.zeros(3, 7), torch.zeros(3, 5, 4))
    with pytest.raises(ValueError, match=r"body joints must have shape \(\.\.\., 7\)"):
        arm.palm_frame(torch.zeros(2, 6))
    with pytest.raises(ValueError, match=r"has no arm"):
        hand.palm_frame(torch.zeros(7))


def test_unknown_finger_name(hand):
    with pytest.raises(gt.ConfigError, match=r"no finger 'little'.*pinky"):
        hand.finger_index("little")


def test_thumb_can_oppose_index_and_middle(hand):
    """The thumb's base is placed like a human thumb: its tip reaches the tips of the flexed
    index and middle fingers (tip-to-tip pinch), within joint limits."""
    from graspnet_torch.jobs.inspect_robots import pinch_posture

    for finger in ("index", "middle", "ring", "pinky"):
        posture, gap = pinch_posture(hand, finger, hand.home_posture())
        assert gap < 1e-4, finger
        lo, hi = hand.finger_limits
        assert (posture.fingers.numpy() >= lo - 1e-12).all() and (posture.fingers.numpy() <= hi + 1e-12).all()


def test_joints_to_file_for_many_postures_equal_each_alone_in_degrees():
    """The batched conversion to file units gives, bit for bit, what converting each posture's
    joint values alone with math.degrees gives (mimic joints included)."""
    import math

    import graspnet_torch as gt

    robot = gt.load_robot("hand")
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = lo + (hi - lo) * torch.rand(50, *lo.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    many = robot.finger_joints_to_file_many(q)
    for k in range(50):
        alone = {name: [math.degrees(v) if t == "revolute" else v
                        for v, t in zip(values, robot.fingers[name].chain.spec.joint_types, strict=True)]
                 for name, values in robot.finger_joint_values(q[k]).items()}
        assert many[k] == alone


def test_subtree_is_the_palm_and_what_it_carries():
    arm = gt.load_robot("arm_hand")
    below = arm.urdf.subtree("palm")
    assert "palm" in below and {c.tip for c in arm.cfg.fingers.values()} <= below
    assert "torso" not in below and "elbow_flexion_link" not in below
    assert arm.urdf.subtree("torso") == frozenset(arm.urdf.link_names)
