"""The chain-level frames of robot/frames.py against pytorch-kinematics' link frames (float64),
an independent forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import graspnet_torch as gt
from graspnet_torch.robot.frames import (
    Attachment,
    RobotLevels,
    frames_at_zero,
    link_attachments,
    motion_terms,
    riding_base_links,
)
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import pose_to_rt

PK_ATOL = 1e-6  # pytorch-kinematics' frames differ from the robot's own chain products by up to ~1.2e-7 (measured)


def _random_posture(robot, T: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """body (T, m), palm pose (T, 6), fingers (T, F, n) within the limits, float64."""
    g = torch.Generator().manual_seed(seed)
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    body = lo + (hi - lo) * torch.rand(T, len(lo), generator=g, dtype=torch.float64)
    palm = torch.cat([torch.rand(T, 3, generator=g, dtype=torch.float64) - 0.5,
                      (torch.rand(T, 3, generator=g, dtype=torch.float64) * 2 - 1) * 3.0], 1)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    fingers = flo + (fhi - flo) * torch.rand(T, *flo.shape, generator=g, dtype=torch.float64)
    return body, palm, fingers


def test_motion_terms_give_rodrigues_rotations_and_translations():
    """I + sin(q) A + (1 - cos(q)) B is the rotation by q about a revolute axis (scipy's rotation
    vector), and I + q A the translation by q along a prismatic one."""
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(4, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    A, B, revolute = motion_terms(axes, ("revolute", "prismatic", "revolute", "prismatic"))
    assert revolute.tolist() == [True, False, True, False]
    for k, q in enumerate(rng.uniform(-3, 3, size=4)):
        if revolute[k]:
            M = np.eye(4) + np.sin(q) * A[k] + (1 - np.cos(q)) * B[k]
            np.testing.assert_allclose(M[:3, :3], Rotation.from_rotvec(q * axes[k]).as_matrix(), atol=1e-12)
            np.testing.assert_allclose(M[:3, 3], 0.0, atol=0)
        else:
            M = np.eye(4) + q * A[k]
            np.testing.assert_allclose(M[:3, :3], np.eye(3), atol=0)
            np.testing.assert_allclose(M[:3, 3], q * axes[k], atol=1e-12)


def _joint_motion(axis: np.ndarray, kind: str, q: float) -> np.ndarray:
    """(4, 4) a joint's motion: scipy's rotation about the axis, or a translation along it."""
    M = np.eye(4)
    if kind == "revolute":
        M[:3, :3] = Rotation.from_rotvec(q * axis).as_matrix()
    else:
        M[:3, 3] = q * axis
    return M


@pytest.mark.parametrize("name", ["arm_hand", "manus"])
def test_body_levels_and_palm_follow_the_chain_and_the_link_frames(name):
    """Level k of the body chain is F_0 M_0(q_0) ... F_{k-1} M_{k-1}(q_{k-1}) (scipy rotations),
    and its end P_m F_m is the palm of pytorch-kinematics and of the robot's kernel."""
    robot = gt.load_robot(name)
    levels = RobotLevels(robot, torch.float64)
    body, _palm, _fingers = _random_posture(robot, 4, seed=1)
    P, (R, t) = levels.body_levels_and_palm(body)
    spec = robot.body
    assert len(P) == spec.n_joints
    R0, t0 = robot.palm_frame(body)
    assert torch.allclose(R, R0, atol=1e-12) and torch.allclose(t, t0, atol=1e-12)
    home = robot.home_posture()
    for k in range(4):
        want = np.eye(4)
        for i in range(spec.n_joints):
            want = want @ spec.offsets[i] @ _joint_motion(spec.axes[i], spec.joint_types[i], float(body[k, i]))
            np.testing.assert_allclose(P[i][k].numpy(), want, atol=1e-12)
        palm = robot.link_frames(Posture(palm_pose=home.palm_pose, fingers=home.fingers, body=body[k]))[
            robot.cfg.palm_link]
        np.testing.assert_allclose(R[k].numpy(), palm[:3, :3], atol=PK_ATOL)
        np.testing.assert_allclose(t[k].numpy(), palm[:3, 3], atol=PK_ATOL)
    assert [p.shape for p in levels.body_levels(body, 3)] == [(4, 4, 4)] * 3


@pytest.mark.parametrize("name", ["hand", "arm_hand", "manus"])
def test_every_link_hangs_from_its_level_frame(name):
    """For every link with a collision shape, its attachment's level frame (from RobotLevels)
    times its pose there is the link's frame from pytorch-kinematics, at random postures."""
    robot = gt.load_robot(name)
    links = [s.link for s in link_shapes(robot.urdf, "collision")]
    attach = link_attachments(robot, links)
    assert set(attach) == set(links)
    levels = RobotLevels(robot, torch.float64)
    body, palm_pose, fingers = _random_posture(robot, 3, seed=2)
    if robot.has_body:
        P, (R, t) = levels.body_levels_and_palm(body)
    else:
        P, (R, t) = [], pose_to_rt(palm_pose)
    W = torch.cat([R, t.unsqueeze(-1)], -1)
    finger_frames = levels.finger_levels(W, fingers, max((a.level for a in attach.values()), default=0)) \
        if robot.n_fingers else []
    for k in range(3):
        posture = Posture(palm_pose=palm_pose[k], fingers=fingers[k], body=body[k])
        frames = robot.link_frames(posture)
        for link, a in attach.items():
            if a.kind == "body":
                level = np.eye(4) if a.level == 0 else P[a.level - 1][k].numpy()
            elif a.kind == "palm":
                level = np.vstack([W[k].numpy(), [0, 0, 0, 1]])
            else:
                level = np.vstack([finger_frames[a.level][k, a.finger].numpy(), [0, 0, 0, 1]])
            np.testing.assert_allclose(level @ a.pose, frames[link], atol=PK_ATOL, err_msg=link)


def test_attachments_of_the_hand_and_the_riding_base_links():
    """The free hand's palm link hangs from the palm, its distal links from the last level of
    their finger; the manus's platform rides its planar base, and no link of the arm_hand (no
    mobile base) or of a base that lifts does."""
    hand = gt.load_robot("hand")
    attach = link_attachments(hand, ["palm", "index_distal"])
    assert (attach["palm"].kind, attach["palm"].level) == ("palm", 0)
    distal = attach["index_distal"]
    assert distal.kind == "finger" and distal.finger == hand.finger_index("index")
    assert distal.level == hand.fingers["index"].chain.spec.n_joints
    manus = gt.load_robot("manus")
    attach = link_attachments(manus, [s.link for s in link_shapes(manus.urdf, "collision")])
    assert riding_base_links(manus, attach) == {"platform", "arm_mount"}
    assert riding_base_links(gt.load_robot("arm_hand"), {"torso": Attachment("body", 0)}) == set()
    assert riding_base_links(manus, {"platform": Attachment("body", 4)}) == set()  # beyond the base joints
    zero = frames_at_zero(manus)
    np.testing.assert_allclose(zero[manus.urdf.root_link], np.eye(4), atol=1e-12)



@pytest.mark.parametrize("name", ["hand", "arm_hand"])
def test_tip_frames_from_link_frames_are_the_fingertips_kinematics(name):
    """Robot.tip_frames_at (the tip links' frames and tip offsets read off link_frames_array) puts
    every fingertip where the fingers' own kinematics (fingertips_world) does, in a batch of random
    postures; points_on_links without offsets gives the links' origins."""
    robot = gt.load_robot(name)
    gen = torch.Generator().manual_seed(4)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    postures = []
    for _ in range(5):
        q = flo + (fhi - flo) * torch.rand(flo.shape, generator=gen, dtype=torch.float64)
        if robot.body is not None:
            lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
            body = lo + (hi - lo) * torch.rand(lo.shape, generator=gen, dtype=torch.float64)
            postures.append(gt.Posture(torch.zeros(6, dtype=torch.float64), q, body))
        else:
            pose = torch.cat([0.1 * torch.rand(3, generator=gen, dtype=torch.float64),
                              torch.rand(3, generator=gen, dtype=torch.float64)])
            postures.append(gt.Posture(pose, q, torch.zeros(0)))
    links, frames = robot.link_frames_array(postures)
    _, tips = robot.tip_frames_at(links, frames, robot.finger_names)
    for p, t in zip(postures, tips, strict=True):
        expected = robot.fingertips_world_from_body(p.body, p.fingers) if robot.body is not None else \
            robot.fingertips_world(p.palm_pose, p.fingers)
        np.testing.assert_allclose(t, expected.numpy(), atol=1e-9)
    _, origins = robot.points_on_links(links, frames, [robot.cfg.palm_link])
    np.testing.assert_allclose(origins[:, 0], frames[:, links.index(robot.cfg.palm_link), :3, 3])
