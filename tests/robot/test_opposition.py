"""Which way a hand grasps, from its kinematics (graspnet_torch/robot/opposition.py): the opposing
finger, the palm's front and the default fingers of a grasp, on the shipped hand, TriFinger and
the public example hands, each against what its URDF says independently; a hand whose pads
cannot oppose is refused in one line by the synthesis command."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.opposition import default_fingers, hand_axes
from tests.refusals import refused

EXAMPLES = repo_root() / "examples"
HANDS = {  # public hand -> its opposing finger, where the hand has one finger unlike the others
    "allegro_hand/allegro_hand_right.yaml": "thumb",
    "leap_hand/leap_hand_right.yaml": "thumb",
    "shadow_hand/shadow_hand_right.yaml": "thumb",
    "barrett_hand/barrett_hand.yaml": None,
    "dclaw_gripper/dclaw_gripper.yaml": None,
}


def test_the_shipped_hand_opposes_its_thumb_and_its_palm_faces_where_its_box_does():
    robot = gt.load_robot("hand")
    axes = hand_axes(robot)
    assert axes.opposing == "thumb" and default_fingers(robot) == ("thumb", "index", "middle")
    assert axes.opposition[0] < -0.9 and (axes.opposition[1:] > 0.4).all()
    box = next(s for s in link_shapes(robot.urdf) if s.link == "palm" and s.kind == "box")
    thin = box.origin[:3, int(np.argmin(box.size))]  # the palm box's thinnest axis: its face's normal
    np.testing.assert_allclose(np.abs(axes.front @ thin), 1.0, atol=1e-12)
    tips = robot.fingertips_palm(robot.home_posture().fingers).numpy()
    assert ((tips - box.origin[:3, 3]) @ axes.front > 0).all()  # the fingertips lie on the front side


def test_trifinger_opposes_any_of_its_alike_fingers_and_uses_all_three():
    robot = gt.load_robot(EXAMPLES / "trifinger" / "trifinger.yaml")
    axes = hand_axes(robot)
    np.testing.assert_allclose(axes.opposition, axes.opposition[0], atol=1e-6)
    assert default_fingers(robot) == ("f0", "f120", "f240")


@pytest.mark.parametrize("config", sorted(HANDS))
def test_a_public_hand_grasps_in_front_of_its_palm_with_three_fingers(config):
    robot = gt.load_robot(EXAMPLES / config)
    axes = hand_axes(robot)
    if HANDS[config] is not None:
        assert axes.opposing == HANDS[config]
    fingers = default_fingers(robot)
    assert len(fingers) == 3 and fingers[0] == axes.opposing and set(fingers) <= set(robot.finger_names)
    assert "thumb" in fingers or "thumb" not in robot.finger_names
    np.testing.assert_allclose(np.linalg.norm(axes.front), 1.0, atol=1e-12)
    lo, hi = (torch.as_tensor(np.asarray(a)) for a in robot.finger_limits)
    closing = robot.fingertips_palm(lo + 0.5 * (hi - lo)).numpy()  # every joint at mid-range
    palm = [s for s in link_shapes(robot.urdf) if s.link == robot.cfg.palm_link]
    centre = np.mean([s.origin[:3, 3] for s in palm], axis=0) if palm else np.zeros(3)
    assert (closing.mean(axis=0) - centre) @ axes.front > 0  # the fingers close on the front side


def _same_side_hand(tmp_path):
    """The shipped hand with only its index and middle fingers: both pads face the palm's front."""
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data["fingers"] = {f: data["fingers"][f] for f in ("index", "middle")}
    data.update(name="two_alike", urdf=str(repo_root() / "urdf" / "hand" / "hand.urdf"), home={})
    path = tmp_path / "robot" / "two_alike.yaml"
    path.parent.mkdir()
    path.write_text(yaml.safe_dump(data))
    return path


def test_fingers_that_cannot_oppose_are_refused_naming_their_angles(tmp_path):
    config = _same_side_hand(tmp_path)
    with pytest.raises(ConfigError, match=r"no finger's pad opposes the others'.*index \d+, middle \d+"):
        hand_axes(gt.load_robot(config))
    mesh = tmp_path / "ball.obj"
    import trimesh

    trimesh.creation.icosphere(subdivisions=2, radius=0.03).export(mesh)
    out = tmp_path / "out"
    line = refused(tmp_path, "synthesize_grasps.py", f"robot={config}", f"objects={mesh}", f"out={out}",
                   message="no finger's pad opposes the others'")
    assert "two_alike.yaml: fingers:" in line and not out.exists()


def test_a_thumb_whose_closing_side_faces_away_gets_its_pad_on_the_side_that_faces_the_fingers():
    robot = gt.load_robot(EXAMPLES / "allegro_hand" / "allegro_hand_right.yaml")
    assert hand_axes(robot).opposing == "thumb" and robot.cfg.fingers["thumb"].pad is not None
    lo, hi = (torch.as_tensor(np.asarray(a)) for a in robot.finger_limits)
    home = robot.home_posture()
    postures = [home.fingers, *(lo + u * (hi - lo) for u in (0.25, 0.5, 0.75))]

    def closing(q):  # the thumb tip's move as its last joint turns toward the palm (finite differences), tip frame
        k, n = robot.finger_index("thumb"), robot.fingers["thumb"].n_joints
        moves = []
        for sign in (1.0, -1.0):
            moved = q.clone()
            moved[k, n - 1] += sign * 1e-6
            moves.append(robot.fingertips_palm(moved)[k] - robot.fingertips_palm(q)[k])
        tip = robot.fingertips_palm(q)[k]
        move = min(moves, key=lambda m: float((tip + m).norm()))  # nearer the palm frame's origin
        R = robot.link_frames(replace(home, fingers=q))[robot.cfg.fingers["thumb"].tip][:3, :3]
        return R.T @ (move / move.norm()).numpy()

    def least_opposition(thumb_normal):  # the thumb's pad normal against the others', at its best posture
        out = []
        for q in postures:
            frames = robot.link_frames(replace(home, fingers=q))
            n = [frames[robot.cfg.fingers[f].tip][:3, :3] @ robot.pads[f].normal for f in robot.finger_names[1:]]
            R = frames[robot.cfg.fingers["thumb"].tip][:3, :3]
            out.append(float((R @ (closing(q) if thumb_normal is None else thumb_normal)) @ np.mean(n, axis=0)))
        return min(out)

    facing = least_opposition(robot.pads["thumb"].normal)
    assert facing < -0.9 and facing < least_opposition(None) - 0.2  # its closing side faces the fingers far less
    for f in robot.finger_names[1:]:  # the others' pads stay on their closing sides
        np.testing.assert_allclose(robot.pads[f].normal, robot.pads["index"].normal, atol=1e-9)


def test_a_finger_with_no_geometry_and_no_pad_is_refused_naming_it(tmp_path):
    urdf = (repo_root() / "urdf" / "hand" / "hand.urdf").read_text()
    start = urdf.index('<link name="index_distal">')
    end = urdf.index("</link>", start)
    link = urdf[start:end]
    bare = link
    while "<collision" in bare:  # the index finger's distal link without its collision shapes
        a = bare.index("<collision")
        bare = bare[:a] + bare[bare.index("</collision>", a) + len("</collision>"):]
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "bare.urdf").write_text(urdf[:start] + bare + urdf[end:])
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data.update(name="bare", urdf="bare.urdf")
    config = tmp_path / "robot" / "bare.yaml"
    config.write_text(yaml.safe_dump(data))
    mesh = tmp_path / "ball.obj"
    import trimesh

    trimesh.creation.icosphere(subdivisions=2, radius=0.03).export(mesh)
    out = tmp_path / "out"
    line = refused(tmp_path, "synthesize_grasps.py", f"robot={config}", f"objects={mesh}", f"out={out}",
                   message="fingers.index: no pad can be derived")
    assert "'index_distal'" in line and "fingers.index.pad" in line and not out.exists()
