"""Every shipped URDF validates (yourdfpy), loads (pytorch-kinematics), is up to date with its
generator, and gives every body link primitive collision geometry."""

from __future__ import annotations

import subprocess
import sys

import pytest

from graspnet_torch.paths import repo_root, urdf_dir
from graspnet_torch.robot import UrdfModel
from graspnet_torch.robot.geometry import link_shapes

URDFS = ["hand/hand.urdf", "arm_hand/arm_hand.urdf", "manus/manus.urdf"]
# links that are pure frames (no body): finger bases and tips, gripper points' parents aside,
# zero-length intermediate links between joints that share an origin, and the mobile base's
# virtual x / y stages.
FRAME_LINKS = {
    "hand/hand.urdf": {f"{f}_{s}" for f in ("thumb", "index", "middle", "ring", "pinky") for s in ("base", "tip")},
    # the gripper points are markers (drawn, not bodies): the jaws touch the object
    "manus/manus.urdf": {"world", "base_x", "base_y", "wrist_pitch_link", "gripper_point_1", "gripper_point_2"},
}
FRAME_LINKS["arm_hand/arm_hand.urdf"] = FRAME_LINKS["hand/hand.urdf"] | {
    "shoulder_flexion_link", "wrist_pronation_link", "wrist_flexion_link", "wrist_deviation_link"}


@pytest.mark.parametrize("rel", URDFS)
def test_validates_with_yourdfpy(rel):
    yourdfpy = pytest.importorskip("yourdfpy")
    model = yourdfpy.URDF.load(str(urdf_dir() / rel), build_scene_graph=True, load_meshes=False)
    assert model.validate()


@pytest.mark.parametrize("rel", URDFS)
def test_loads_with_pytorch_kinematics(rel):
    model = UrdfModel(urdf_dir() / rel)
    assert len(model.chain.get_joint_parameter_names()) == len(model.movable_joint_names)


@pytest.mark.parametrize("rel", URDFS)
def test_body_links_have_primitive_collision_geometry(rel):
    model = UrdfModel(urdf_dir() / rel)
    shapes = link_shapes(model)
    assert {s.kind for s in shapes} <= {"box", "cylinder", "sphere"}
    without = set(model.link_names) - {s.link for s in shapes}
    assert without == FRAME_LINKS[rel]


def test_urdfs_are_up_to_date_with_generator():
    res = subprocess.run([sys.executable, str(repo_root() / "urdf" / "build.py"), "--check"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


def test_arm_hand_reuses_the_hand():
    """One source of truth: the hand's links and joints appear unchanged inside arm_hand."""
    import xml.etree.ElementTree as ET

    hand = ET.parse(urdf_dir() / "hand/hand.urdf").getroot()
    arm = ET.parse(urdf_dir() / "arm_hand/arm_hand.urdf").getroot()
    arm_items = {(el.tag, el.get("name")): ET.tostring(el) for el in arm}
    for el in hand:
        if el.tag in ("link", "joint"):
            assert arm_items[(el.tag, el.get("name"))] == ET.tostring(el)
