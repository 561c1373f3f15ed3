"""A free hand whose URDF has a wrist: movable joints between its root (a forearm) and the palm.

The hand is the shipped ``urdf/hand/hand.urdf`` with a forearm (a box) and a wrist link (a
cylinder) added above ``palm`` through two revolute joints, ``wrj2`` (about y) then ``wrj1``
(about x). The robot holds them at the config's ``wrist`` values (degrees), else 0; the links
above the palm are rigid with it there. yourdfpy is the independent oracle of the frames.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.frames import link_attachments
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from tests.mujoco_models import posed_model

WRIST_LIMITS = {"wrj2": (-0.5, 0.2), "wrj1": (-0.7, 0.5)}  # rad
PALM = np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])  # a palm pose (m, rad)
FINGERS = ({"base": "thumb_base", "tip": "thumb_tip"}, {"base": "index_base", "tip": "index_tip"},
           {"base": "middle_base", "tip": "middle_tip"})

needs_mujoco = pytest.mark.skipif(importlib.util.find_spec("mujoco") is None,
                                  reason="the physics check needs MuJoCo (pip install mujoco; the dev extra has it)")


def wrist_urdf(limits: dict[str, tuple[float, float]] = WRIST_LIMITS) -> str:
    """The shipped hand with a forearm and two wrist joints above its palm."""
    text = (repo_root() / "urdf" / "hand" / "hand.urdf").read_text()
    (lo2, hi2), (lo1, hi1) = limits["wrj2"], limits["wrj1"]
    extra = f"""
  <link name="forearm">
    <collision><origin xyz="0 0 -0.1"/><geometry><box size="0.06 0.04 0.2"/></geometry></collision>
  </link>
  <link name="wrist_link">
    <collision><origin xyz="0 0 0" rpy="1.5708 0 0"/><geometry><cylinder radius="0.015" length="0.04"/>
    </geometry></collision>
  </link>
  <joint name="wrj2" type="revolute"><parent link="forearm"/><child link="wrist_link"/>
    <origin xyz="0.005 0 0.03" rpy="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="{lo2}" upper="{hi2}" effort="10" velocity="1"/></joint>
  <joint name="wrj1" type="revolute"><parent link="wrist_link"/><child link="palm"/>
    <origin xyz="0 0 0.035" rpy="0.1 0 0"/><axis xyz="1 0 0"/>
    <limit lower="{lo1}" upper="{hi1}" effort="10" velocity="1"/></joint>
</robot>"""
    return text.replace("</robot>", extra)


def write_wrist_hand(folder: Path, wrist: dict | None = None, limits: dict = WRIST_LIMITS, **extra) -> Path:
    """The wrist hand's URDF and a robot config (thumb, index, middle) in ``folder``: the YAML's path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "wrist_hand.urdf").write_text(wrist_urdf(limits))
    cfg = {"name": "wrist_hand", "urdf": "wrist_hand.urdf", "palm_link": "palm",
           "fingers": dict(zip(("thumb", "index", "middle"), FINGERS, strict=True)), **extra}
    if wrist is not None:
        cfg["wrist"] = wrist
    path = folder / "wrist_hand.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def oracle_frames(robot, posture: gt.Posture, links: list[str]) -> dict[str, np.ndarray]:
    """yourdfpy's world frames of ``links``: the URDF at the posture's joints and the robot's held
    wrist, placed so that the palm sits at the posture's palm pose."""
    yourdfpy = pytest.importorskip("yourdfpy")
    model = yourdfpy.URDF.load(str(robot.cfg.urdf), load_meshes=False, build_scene_graph=True)
    values = robot.joint_values(posture)
    model.update_cfg({name: values.get(name, 0.0) for name in model.actuated_joint_names})
    root = model.base_link
    world = pose_to_matrix_np(posture.palm_pose.numpy()) @ np.linalg.inv(model.get_transform("palm", root))
    return {link: world @ model.get_transform(link, root) for link in links}


@pytest.fixture(scope="module")
def wrist_hand(tmp_path_factory):
    return gt.load_robot(write_wrist_hand(tmp_path_factory.mktemp("wrist"), {"wrj2": -20, "wrj1": 15}))


def posture_of(robot) -> gt.Posture:
    gen = torch.Generator().manual_seed(0)
    lower, upper = (torch.as_tensor(a) for a in robot.finger_limits)
    fingers = lower + (upper - lower) * torch.rand(lower.shape, generator=gen, dtype=torch.float64)
    return gt.Posture(torch.as_tensor(PALM), fingers, torch.zeros(0, dtype=torch.float64))


def test_a_wrist_config_loads_with_its_joints_held(wrist_hand):
    assert wrist_hand.kind == "hand" and wrist_hand.shared.n == 0
    assert wrist_hand.wrist == pytest.approx({"wrj2": math.radians(-20), "wrj1": math.radians(15)}, abs=1e-15)
    assert wrist_hand.dof == wrist_hand.n_finger_joints + 6  # the wrist is no degree of freedom


def test_unset_wrist_joints_are_held_at_zero(tmp_path):
    robot = gt.load_robot(write_wrist_hand(tmp_path, {"wrj1": -10}))
    assert robot.wrist == pytest.approx({"wrj2": 0.0, "wrj1": math.radians(-10)}, abs=1e-15)


def test_links_above_the_palm_follow_the_held_wrist(wrist_hand):
    posture = posture_of(wrist_hand)
    frames = wrist_hand.link_frames(posture)
    links = ["forearm", "wrist_link", "palm", "thumb_tip", "index_tip", "middle_tip"]
    expected = oracle_frames(wrist_hand, posture, links)
    for link in links:
        np.testing.assert_allclose(frames[link], expected[link], atol=1e-9, err_msg=link)
    np.testing.assert_allclose(frames["palm"], pose_to_matrix_np(PALM), atol=1e-12)
    tips = wrist_hand.fingertips_world(posture.palm_pose, posture.fingers).numpy()
    np.testing.assert_allclose(tips, [frames[f"{f}_tip"][:3, 3] for f in ("thumb", "index", "middle")], atol=1e-12)


def test_the_forearm_moves_with_the_wrist_value(tmp_path):
    a = gt.load_robot(write_wrist_hand(tmp_path / "a", {"wrj2": -20}))
    b = gt.load_robot(write_wrist_hand(tmp_path / "b", {"wrj2": 10}))
    posture = posture_of(a)
    fa, fb = a.link_frames(posture), b.link_frames(posture)
    np.testing.assert_allclose(fa["palm"], fb["palm"], atol=1e-12)
    assert np.linalg.norm(fa["forearm"][:3, 3] - fb["forearm"][:3, 3]) > 0.01


def test_the_collision_proxy_keeps_the_forearm_rigid_with_the_palm_at_the_held_wrist(wrist_hand):
    attach = link_attachments(wrist_hand, ["forearm", "wrist_link"])
    assert attach["forearm"].kind == "palm" and attach["wrist_link"].kind == "palm"
    np.testing.assert_allclose(attach["forearm"].pose, np.linalg.inv(wrist_hand.root_to_palm()), atol=1e-12)


def test_held_wrist_joints_do_not_count_as_moving_for_self_collision(tmp_path):
    from graspnet_torch.collision.scene import self_collision_pairs

    robot = gt.load_robot(write_wrist_hand(tmp_path, {"wrj2": -20}, self_collision=True))
    pairs = {frozenset(p) for p in self_collision_pairs(robot)}
    assert frozenset(("forearm", "palm")) not in pairs  # rigid with each other at the held wrist
    assert any("forearm" in p and "index_distal" in p for p in pairs)


@pytest.mark.parametrize(("wrist", "limits", "message"), [
    ({"wrj2": 30}, WRIST_LIMITS, r"wrist\.wrj2: 30 is outside the joint's limits \[-28.6\d*, 11.4\d*\] degrees"),
    ({"wrj3": 5}, WRIST_LIMITS, r"wrist\.wrj3: not a movable joint between the URDF root 'forearm' and "
                                r"palm_link 'palm' \(those are: wrj2, wrj1\)"),
    ({}, {"wrj2": (0.1, 0.3), "wrj1": (-0.7, 0.5)}, r"wrist joint 'wrj2' .* held at 0 by default, outside its "
                                                     r"limits .*; set wrist\.wrj2"),
])
def test_a_bad_wrist_is_one_line_naming_the_key(tmp_path, wrist, limits, message):
    path = write_wrist_hand(tmp_path, wrist, limits)
    with pytest.raises(ConfigError, match=message) as err:
        gt.load_robot(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_a_wrist_on_a_hand_without_one_is_refused(tmp_path):
    path = tmp_path / "hand.yaml"
    cfg = yaml.safe_load((repo_root() / "configs" / "robot" / "hand.yaml").read_text())
    path.write_text(yaml.safe_dump({**cfg, "urdf": str(repo_root() / "urdf" / "hand" / "hand.urdf"),
                                    "wrist": {"wrj1": 5}}))
    with pytest.raises(ConfigError, match=r"wrist\.wrj1: not a movable joint .*\(those are: none\)"):
        gt.load_robot(path)


def test_wrist_with_an_arm_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"'wrist' .* with 'arm'") as err:
        RobotCfg.from_mapping({"name": "x", "urdf": "x.urdf", "palm_link": "palm", "fingers": {"a": {"tip": "t"}},
                               "arm": {"base": "base", "tip": "palm"}, "wrist": {"wrj1": 5}}, source="x.yaml")
    assert "\n" not in str(err.value) and "x.yaml" in str(err.value)


def test_a_hand_without_a_wrist_is_unchanged(hand):
    assert hand.wrist == {}
    np.testing.assert_array_equal(hand.root_to_palm(), hand.urdf.fixed_transform(hand.urdf.root_link, "palm"))


@needs_mujoco
def test_the_physics_model_holds_the_forearm_where_the_wrist_puts_it(wrist_hand):
    obj = Shape.from_mapping({"shape": "sphere", "size": [0.03], "pose": [0.3, 0, 0, 0, 0, 0]}, "object")
    posture = posture_of(wrist_hand)
    model, data, _ = posed_model(wrist_hand, obj, posture)
    joints = {model.joint(k).name for k in range(model.njnt)}
    assert not joints & {"wrj1", "wrj2"} and model.nu == len(wrist_hand.urdf.movable_joint_names) - 2  # welded
    expected = oracle_frames(wrist_hand, posture, ["forearm", "wrist_link", "palm"])
    for link, T in expected.items():
        body = model.body(link).id
        np.testing.assert_allclose(data.xpos[body], T[:3, 3], atol=1e-6, err_msg=link)
        np.testing.assert_allclose(data.xmat[body].reshape(3, 3), T[:3, :3], atol=1e-6, err_msg=link)


def test_a_wrist_outside_its_limits_is_refused_by_the_command_with_exit_2(tmp_path):
    from tests.refusals import refused

    path = write_wrist_hand(tmp_path / "robot", {"wrj2": 30})
    mesh = tmp_path / "ball.obj"
    import trimesh

    trimesh.creation.icosphere(subdivisions=2, radius=0.03).export(mesh)
    out = tmp_path / "out"
    refused(tmp_path, "synthesize_grasps.py", f"robot={path}", f"objects={mesh}", f"out={out}",
            message="wrist.wrj2: 30 is outside the joint's limits")
    assert not out.exists()
