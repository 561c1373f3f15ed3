"""Robot.link_frames_of (the whole URDF as one TreeKernel) against pytorch-kinematics, the
independent oracle: every link of every shipped robot, the TriFinger, a hand with mimic joints and
odd fingers (alone and on an arm) and a hand whose fingers share joints, at random joint values.

pytorch-kinematics parses origins and axes in float32; the oracle here is its chain built in
float64 (its own rpy -> quaternion -> matrix in float64), so the two agree to 1e-9."""

from __future__ import annotations

import importlib.util
import types

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.paths import repo_root
from graspnet_torch.robot import available_robots
from graspnet_torch.robot.kernel import ChainKernel, TreeKernel
from graspnet_torch.robot.transforms import pose_to_matrix
from tests.odd_hands import write_coupled_hand, write_odd_arm, write_oddhand

pk = pytest.importorskip("pytorch_kinematics")
import pytorch_kinematics.transforms as pk_tf  # noqa: E402
import pytorch_kinematics.urdf as pk_urdf  # noqa: E402
from pytorch_kinematics.urdf_parser_py.urdf import URDF  # noqa: E402

TRIFINGER = repo_root() / "examples" / "trifinger" / "trifinger.yaml"
HAS_TRIFINGER = importlib.util.find_spec("robot_properties_fingers") is not None


def pk_chain64(xml: bytes):
    """pytorch-kinematics' chain of a URDF with its origins and axes in float64 (its parser
    rounds them to float32: ~1e-8 off)."""

    def transform(origin):
        if origin is None:
            return pk_tf.Transform3d(dtype=torch.float64)
        rpy = torch.tensor(origin.rpy, dtype=torch.float64)
        return pk_tf.Transform3d(rot=pk_tf.quaternion_from_euler(rpy, "sxyz"),
                                 pos=torch.tensor(origin.xyz, dtype=torch.float64), dtype=torch.float64)

    class Joint64(pk.frame.Joint):
        def __init__(self, *args, **kwargs):
            kwargs["dtype"] = torch.float64
            super().__init__(*args, **kwargs)

    saved = pk_urdf._convert_transform, pk_urdf.frame.Joint, pk_urdf.chain
    pk_urdf._convert_transform, pk_urdf.frame.Joint = transform, Joint64
    pk_urdf.chain = types.SimpleNamespace(Chain=lambda root: saved[2].Chain(root, dtype=torch.float64))
    try:
        return pk.build_chain_from_urdf(xml)
    finally:
        pk_urdf._convert_transform, pk_urdf.frame.Joint, pk_urdf.chain = saved


def random_joints(robot, B: int, gen: torch.Generator):
    """Random body (B, m) or None, fingers (B, F, n), palm poses (B, 6) or None, shared (B, S) or None."""

    def within(lo, hi):
        lo, hi = torch.as_tensor(lo, dtype=torch.float64), torch.as_tensor(hi, dtype=torch.float64)
        return lo + (hi - lo) * torch.rand(B, *lo.shape, generator=gen, dtype=torch.float64)

    fingers = within(*robot.finger_limits)
    body = within(*robot.body_limits) if robot.body is not None else None
    pose = None if robot.body is not None else torch.cat(
        [torch.randn(B, 3, generator=gen, dtype=torch.float64) * 0.2,
         (torch.rand(B, 3, generator=gen, dtype=torch.float64) * 2 - 1) * 3.0], 1)
    shared = torch.as_tensor(within(robot.shared.lower, robot.shared.upper)) if robot.shared.n else None
    return body, fingers, pose, shared


def oracle_joints(robot, names: list[str], body, fingers, shared) -> torch.Tensor:
    """pytorch-kinematics' joint vector (B, J): the free joints given, every mimic joint from the
    URDF's own numbers (its leader's value times the multiplier plus the offset), others 0."""
    B = fingers.shape[0]
    values: dict[str, torch.Tensor] = {}
    if body is not None:
        values.update(zip(robot.body_joint_names, body.unbind(1), strict=True))
    for k, f in enumerate(robot.fingers.values()):
        values.update(zip(f.joint_names, fingers[:, k, : f.n_joints].unbind(1), strict=True))
    if shared is not None:
        values.update(zip(robot.shared.names, shared.unbind(1), strict=True))
    mimic = {j.name: j.mimic for j in URDF.from_xml_string(robot.urdf.path.read_bytes()).joints
             if getattr(j, "mimic", None) is not None}
    for _ in range(len(mimic)):  # mimic joints of mimic joints
        for name, m in mimic.items():
            if m.joint in values:
                values[name] = (1.0 if m.multiplier is None else m.multiplier) * values[m.joint] + (m.offset or 0.0)
    th = torch.zeros(B, len(names), dtype=torch.float64)
    for c, name in enumerate(names):
        if name in values:
            th[:, c] = values[name]
    return th


def assert_link_frames_match_oracle(robot, gen: torch.Generator, B: int = 16) -> None:
    body, fingers, pose, shared = random_joints(robot, B, gen)
    names, frames = robot.link_frames_of(body, fingers, pose, shared)
    chain = pk_chain64(robot.urdf.path.read_bytes())
    fk = chain.forward_kinematics(oracle_joints(robot, chain.get_joint_parameter_names(), body, fingers, shared))
    assert names == list(fk)  # the same links in the same order
    want = torch.stack([fk[name].get_matrix().expand(B, 4, 4) for name in names], 1).numpy()
    assert frames.shape == (B, len(names), 4, 4) and frames.dtype == np.float64
    if pose is not None:  # a free hand: the palm where its pose puts it, the rest rigidly with the URDF's root
        palm = names.index(robot.cfg.palm_link)
        np.testing.assert_allclose(frames[:, palm], pose_to_matrix(pose).numpy(), atol=1e-12, rtol=0)
        want = frames[:, palm, None] @ np.linalg.inv(want[:, palm, None]) @ want
    np.testing.assert_allclose(frames, want, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", available_robots())
def test_link_frames_of_every_shipped_robot_match_pytorch_kinematics(name, gen):
    robot = gt.load_robot(name)
    assert_link_frames_match_oracle(robot, gen)


@pytest.mark.skipif(not HAS_TRIFINGER, reason="the TriFinger URDF needs the 'robot_properties_fingers' package")
def test_link_frames_of_the_trifinger_match_pytorch_kinematics(gen):
    assert_link_frames_match_oracle(gt.load_robot(TRIFINGER), gen)


@pytest.mark.parametrize("write", [write_oddhand, write_odd_arm, write_coupled_hand],
                         ids=["mimic", "mimic_on_arm", "shared"])
def test_link_frames_of_mimic_and_shared_joints_match_pytorch_kinematics(write, tmp_path, gen):
    robot = gt.load_robot(write(tmp_path))
    assert robot.urdf.mimic_joints  # every one of these hands has a mimic joint (a shared joint's follower)
    assert_link_frames_match_oracle(robot, gen)


def test_link_frames_hold_shared_joints_at_home_by_default(tmp_path, gen):
    robot = gt.load_robot(write_coupled_hand(tmp_path))
    _, fingers, pose, _ = random_joints(robot, 4, gen)
    held = torch.as_tensor(robot.shared_reference).expand(4, -1)
    np.testing.assert_array_equal(robot.link_frames_of(None, fingers, pose)[1],
                                  robot.link_frames_of(None, fingers, pose, held)[1])


def test_tree_kernel_on_a_serial_chain_is_the_chain_kernel(robots, gen):
    """A chain as a tree (each joint the previous one's child; one link at the tip): the chain
    kernel's tip pose, in float64 and float32."""
    spec = robots["arm_hand"].body
    n = spec.n_joints
    tree = TreeKernel(list(range(-1, n - 1)), spec.joint_types, spec.axes, spec.offsets[:n], [n - 1],
                      spec.offsets[n:])
    q = torch.as_tensor(spec.lower) + torch.as_tensor(spec.upper - spec.lower) * torch.rand(
        64, n, generator=gen, dtype=torch.float64)
    R, p = ChainKernel(spec).pose(q)
    T = tree.frames(q)
    assert T.shape == (64, 1, 4, 4)
    torch.testing.assert_close(T[:, 0, :3, :3], R, atol=1e-13, rtol=0)
    torch.testing.assert_close(T[:, 0, :3, 3], p, atol=1e-13, rtol=0)
    T32 = tree.frames(q.float())
    assert T32.dtype == torch.float32
    torch.testing.assert_close(T32[:, 0, :3, 3].double(), p, atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match=rf"shape \(B, {n}\)"):
        tree.frames(q[:, :-1])
