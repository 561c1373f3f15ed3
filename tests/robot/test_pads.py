"""Finger pads (graspnet_torch.robot.pads): derived from the URDF's distal links and closing
directions, or given by the robot config (read, moved into the tip frame, checked)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.robot.geometry import link_shapes

TRIFINGER = repo_root() / "examples" / "trifinger" / "trifinger.yaml"
HAS_TRIFINGER = importlib.util.find_spec("robot_properties_fingers") is not None
HAND_RADII = {"thumb": 0.008075, "index": 0.007225, "middle": 0.007225, "ring": 0.0068, "pinky": 0.00595}


def _closing_directions(robot: gt.Robot, eps: float = 1e-6) -> dict[str, np.ndarray]:
    """Finger name -> unit direction, in its tip frame, in which the tip moves as its last free
    joint closes at the home posture: increases where its upper limit puts the tip nearer the palm
    frame's origin than its lower limit does, else decreases; finite differences of the link frames
    (an oracle independent of the finger kernels)."""
    home = robot.home_posture()
    frames = robot.link_frames(home)
    lo, hi = (np.asarray(a) for a in robot.finger_limits)
    out = {}
    for k, (name, finger) in enumerate(robot.fingers.items()):
        offset = np.array([*(robot.cfg.fingers[name].tip_offset or (0.0, 0.0, 0.0)), 1.0])
        tip, last = finger.chain.tip, finger.n_joints - 1

        def tip_at(value: float, k=k, last=last, tip=tip, offset=offset) -> np.ndarray:
            moved = home.fingers.clone()
            moved[k, last] = value
            at = robot.link_frames(gt.Posture(home.palm_pose, moved, home.body))
            return (np.linalg.inv(at[robot.cfg.palm_link]) @ at[tip] @ offset)[:3]  # palm frame

        sense = 1.0 if np.linalg.norm(tip_at(hi[k, last])) <= np.linalg.norm(tip_at(lo[k, last])) else -1.0
        moved = home.fingers.clone()
        moved[k, last] += sense * eps
        after = robot.link_frames(gt.Posture(home.palm_pose, moved, home.body))
        before_p, after_p = (frames[tip] @ offset)[:3], (after[tip] @ offset)[:3]
        v = frames[tip][:3, :3].T @ (after_p - before_p)
        out[name] = v / np.linalg.norm(v)
    return out


def _distal_sphere_radius(robot: gt.Robot, link: str) -> float:
    return max(s.size[0] for s in link_shapes(robot.urdf, "collision") if s.link == link and s.kind == "sphere")


@pytest.mark.parametrize("name", ["hand", "arm_hand"])
def test_shipped_hand_pads_are_the_distal_spheres_along_the_closing_direction(robots, name):
    """The four fingers' pads are derived (the distal sphere along the closing direction); the
    thumb's is the config's, on its distal sphere's side that faces the fingers (-z)."""
    robot = robots[name]
    pads = robot.pads
    assert list(pads) == list(robot.finger_names)
    closing = _closing_directions(robot)
    for finger, pad in pads.items():
        assert pad.link == f"{finger}_distal"
        r = _distal_sphere_radius(robot, pad.link)
        assert r == pytest.approx(HAND_RADII[finger])
        assert abs(pad.depth - r) < 1e-4
        side = [0.0, 0.0, -1.0] if finger == "thumb" else [0.0, 1.0, 0.0]  # flexion about z moves a tip to +y
        np.testing.assert_allclose(pad.normal, side, atol=1e-9)
        np.testing.assert_allclose(pad.point, r * np.asarray(side), atol=1e-9)
        if finger != "thumb":
            np.testing.assert_allclose(pad.normal, closing[finger], atol=1e-6)
    assert robot.pads is pads  # cached


def _facing_share(pad_normal: np.ndarray, n: int = 20000) -> float:
    """Of random thumb and index postures (independent FK: pytorch_kinematics on the URDF) whose
    tips lie 30-90 mm apart with the index pad facing the thumb tip within 30 degrees, the share
    where ``pad_normal`` (thumb tip frame) faces the index tip within 30 degrees."""
    import pytorch_kinematics as pk
    import torch

    urdf = (repo_root() / "urdf" / "hand" / "hand.urdf").read_text()
    rng = np.random.default_rng(0)
    frames = {}
    for f in ("thumb", "index"):
        chain = pk.build_serial_chain_from_urdf(urdf, f"{f}_tip", "palm").to(dtype=torch.float64)
        lo, hi = (np.asarray(a) for a in chain.get_joint_limits())
        frames[f] = chain.forward_kinematics(torch.as_tensor(rng.uniform(lo, hi, (n, len(lo))))).get_matrix().numpy()
    d = frames["index"][:, :3, 3] - frames["thumb"][:, :3, 3]
    dist = np.linalg.norm(d, axis=1)
    u = d / dist[:, None]
    to_index = np.einsum("nji,nj->ni", frames["thumb"][:, :3, :3], u)
    to_thumb = np.einsum("nji,nj->ni", frames["index"][:, :3, :3], -u)
    cos30 = np.cos(np.radians(30))
    pinch = (dist > 0.03) & (dist < 0.09) & (to_thumb[:, 1] > cos30)
    assert pinch.sum() > 500
    return float((to_index[pinch] @ pad_normal > cos30).mean())


def test_shipped_thumb_pad_faces_the_fingers_where_its_closing_side_does_not(robots):
    """Why the shipped hand's thumb pad is given: its closing side (+y) almost never faces the
    index finger's pad in a pinch, the configured side (-z) often does."""
    closing = _closing_directions(robots["hand"])["thumb"]
    given = _facing_share(robots["hand"].pads["thumb"].normal)
    derived = _facing_share(closing)
    assert derived < 0.01 and given > 0.2


def test_a_gripper_has_no_pads(robots):
    assert robots["manus"].pads == {}


def _trifinger(tmp_path, pads: bool) -> gt.Robot:
    """The TriFinger example, as shipped (its config's pads) or with the pads left to be derived."""
    data = yaml.safe_load(TRIFINGER.read_text())
    if not pads:
        for finger in data["fingers"].values():
            finger.pop("pad")
    path = tmp_path / "trifinger.yaml"
    path.write_text(yaml.safe_dump(data))
    return gt.load_robot(path)


def _surface_distance(robot: gt.Robot, link: str, point: np.ndarray) -> tuple[float, np.ndarray]:
    import trimesh

    shape = next(s for s in link_shapes(robot.urdf, "collision") if s.link == link and s.kind == "mesh")
    vertices = np.asarray(shape.mesh.vertices) @ shape.origin[:3, :3].T + shape.origin[:3, 3]
    surface = trimesh.Trimesh(vertices, np.asarray(shape.mesh.faces), process=False)
    return float(trimesh.proximity.closest_point(surface, point[None])[1][0]), vertices


@pytest.mark.skipif(not HAS_TRIFINGER, reason="the TriFinger URDF needs the 'robot_properties_fingers' package")
def test_trifinger_derived_pads_lie_on_its_tip_meshes_along_the_closing_direction(tmp_path):
    robot = _trifinger(tmp_path, pads=False)
    pads = robot.pads
    closing = _closing_directions(robot)
    assert set(pads) == {"f0", "f120", "f240"}
    for finger, pad in pads.items():
        assert pad.link == robot.fingers[finger].chain.tip
        np.testing.assert_allclose(pad.normal, closing[finger], atol=1e-6)
        assert np.linalg.norm(pad.normal) == pytest.approx(1.0)
        dist, vertices = _surface_distance(robot, pad.link, pad.point)
        assert dist < 1e-6  # on the tip's surface
        assert pad.depth == pytest.approx(float((vertices @ pad.normal).max()), abs=5e-4)  # the support height
        assert 0.005 < pad.depth < 0.02


@pytest.mark.skipif(not HAS_TRIFINGER, reason="the TriFinger URDF needs the 'robot_properties_fingers' package")
def test_trifinger_config_pads_face_the_holders_axis_where_the_tips_close(tmp_path):
    """The example's pads lie on the tip spheres, and where the three tips close on an object on
    the holder's axis (0.22 m below it, 3 cm from the axis: joints by least squares) they face the
    axis within 10 degrees; the derived pads (the last joint's closing side) face away from it by
    more than 60."""
    from scipy.optimize import least_squares

    (tmp_path / "derived").mkdir()
    robot, other = _trifinger(tmp_path, pads=True), _trifinger(tmp_path / "derived", pads=False)
    home = robot.home_posture()
    lo, hi = (np.asarray(a) for a in robot.finger_limits)
    q = home.fingers.numpy().copy()
    home_tips = robot.fingertips_palm(home.fingers).numpy()
    for i in range(3):
        heading = home_tips[i, :2] / np.linalg.norm(home_tips[i, :2])
        target = np.array([*(0.03 * heading), -0.22])

        def miss(x, i=i, target=target):
            moved = q.copy()
            moved[i] = x
            return robot.fingertips_palm(torch.as_tensor(moved)).numpy()[i] - target

        q[i] = least_squares(miss, q[i], bounds=(lo[i], hi[i])).x
        assert np.linalg.norm(miss(q[i])) < 1e-6
    posture = gt.Posture(home.palm_pose, torch.as_tensor(q), home.body)
    frames = robot.link_frames(posture)
    for k, finger in enumerate(robot.finger_names):
        R = frames[robot.fingers[finger].chain.tip][:3, :3]
        tip = robot.fingertips_palm(torch.as_tensor(q)).numpy()[k]
        to_axis = -np.array([tip[0], tip[1], 0.0]) / np.linalg.norm(tip[:2])
        pad = robot.pads[finger]
        assert _surface_distance(robot, pad.link, pad.point)[0] < 5e-4  # on the tip sphere (radius 10 mm)
        assert np.degrees(np.arccos(R @ pad.normal @ to_axis)) < 10
        assert np.degrees(np.arccos(R @ other.pads[finger].normal @ to_axis)) > 60


def _hand_with(tmp_path, finger: str = "index", **chain) -> gt.Robot:
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data["fingers"][finger] = {"base": f"{finger}_base", "tip": f"{finger}_tip", **chain}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return gt.load_robot(path)


def test_a_config_pad_is_read_and_moved_into_the_tip_frame(tmp_path):
    robot = _hand_with(tmp_path, pad={"link": "index_distal", "point": [0.015, 0.007, 0.001], "normal": [0, 2, 0]})
    cfg = robot.cfg.fingers["index"]
    assert cfg.pad.link == "index_distal" and cfg.pad.normal == (0.0, 1.0, 0.0)
    np.testing.assert_allclose(cfg.pad.point, [0.015, 0.007, 0.001], atol=1e-12)  # where the config put it, on its link
    # the pad point lies off the tip's normal line: the tip (x = 0.01843 on the link) moves across onto it
    np.testing.assert_allclose(cfg.tip_offset, [0.015 - 0.01843, 0.0, 0.001], atol=1e-12)
    pad = robot.pads["index"]
    assert pad.link == "index_distal"
    np.testing.assert_allclose(pad.point, [0.0, 0.007, 0.0], atol=1e-12)
    np.testing.assert_allclose(pad.normal, [0.0, 1.0, 0.0])
    assert pad.depth == pytest.approx(0.007)
    assert robot.pads["middle"].depth == pytest.approx(0.007225)  # the others are still derived
    assert robot.cfg.fingers["middle"].tip_offset is None  # and on their tips' normal lines


def test_a_config_pad_on_the_tip_link_with_a_tip_offset(tmp_path):
    robot = _hand_with(tmp_path, tip={"link": "index_distal", "offset": [0.01, 0.0, 0.0]},
                       pad={"link": "index_distal", "point": [0.01843, 0.0, 0.007225], "normal": [0, 0, 1]})
    pad = robot.pads["index"]
    np.testing.assert_allclose(robot.cfg.fingers["index"].tip_offset, [0.01843, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pad.point, [0.0, 0.0, 0.007225], atol=1e-12)
    np.testing.assert_allclose(pad.normal, [0.0, 0.0, 1.0])
    derived = _hand_with(tmp_path, tip={"link": "index_distal", "offset": [0.01843, 0.0, 0.0]}).pads["index"]
    np.testing.assert_allclose(derived.point, [0.0, 0.007225, 0.0], atol=1e-9)


@pytest.mark.parametrize(("link", "message"), [
    ("index_nail", r"fingers\.index\.pad\.link: link 'index_nail' is not in hand\.urdf"),
    ("middle_distal", r"fingers\.index\.pad\.link: link 'middle_distal' is not the tip link 'index_tip' of finger "
                      r"'index' or one of its ancestors"),
    ("index_middle", r"fingers\.index\.pad\.link: link 'index_middle' is not rigidly attached to the tip 'index_tip' "
                     r"\(revolute joint 'index_dip' between them\)"),
])
def test_a_config_pad_on_a_wrong_link_is_refused_in_one_line(tmp_path, link, message):
    robot = _hand_with(tmp_path, pad={"link": link, "point": [0, 0, 0], "normal": [0, 1, 0]})
    with pytest.raises(gt.ConfigError, match=message) as info:
        _ = robot.pads
    assert "\n" not in str(info.value) and "robot.yaml" in str(info.value)


@pytest.mark.parametrize(("pad", "message"), [
    ({"link": "index_distal", "point": [0, 0, 0], "normal": [0, 0, 0]},
     r"fingers\.index\.pad\.normal: must not be zero"),
    ({"link": "index_distal", "point": [0, 0], "normal": [0, 1, 0]}, r"fingers\.index\.pad\.point: expected 3 numbers"),
    ({"link": "index_distal", "point": [0, 0, 0]}, r"fingers\.index\.pad: expected \{link: <link>, point"),
    ({"link": "", "point": [0, 0, 0], "normal": [0, 1, 0]}, r"fingers\.index\.pad: expected"),
    ({"link": "index_distal", "point": [0, 0, 0], "normal": [0, "up", 0]}, r"fingers\.index\.pad\.normal\[1\]"),
])
def test_a_bad_config_pad_is_refused_when_the_config_loads(tmp_path, pad, message):
    with pytest.raises(gt.ConfigError, match=message) as info:
        _hand_with(tmp_path, pad=pad)
    assert "\n" not in str(info.value) and "robot.yaml" in str(info.value)


def test_pads_do_not_depend_on_the_home_posture(tmp_path):
    """The last joint's closing direction is constant in the tip frame: another home gives the same pads."""
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data["home"] = {"index_mcp": 60, "index_pip": 70, "index_dip": 40, "index_abd": -10}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    bent = gt.load_robot(path).pads["index"]
    straight = gt.load_robot("hand").pads["index"]
    np.testing.assert_allclose(bent.normal, straight.normal, atol=1e-12)
    np.testing.assert_allclose(bent.point, straight.point, atol=1e-12)


def test_a_finger_that_closes_as_its_joint_decreases_gets_the_same_pad(tmp_path):
    """The shipped hand with every finger's last joint mirrored (axis and limits negated, so that
    the finger closes as the joint decreases, as the Dexmate F5D6's and TriFinger's do) derives
    the same pads: the side the finger curls toward, not the side the joint's positive sense moves."""
    import re

    text = (repo_root() / "urdf" / "hand" / "hand.urdf").read_text()
    last = ("index_dip", "middle_dip", "ring_dip", "pinky_dip")

    def mirror(match: re.Match) -> str:
        joint = match.group(0)
        joint = re.sub(r'<axis xyz="0 0 1"/>', '<axis xyz="0 0 -1"/>', joint)
        lower, upper = (float(v) for v in re.search(r'lower="([^"]+)" upper="([^"]+)"', joint).groups())
        return re.sub(r'lower="[^"]+" upper="[^"]+"', f'lower="{-upper}" upper="{-lower}"', joint)

    pattern = r'<joint name="(?:{})" type="revolute">.*?</joint>'.format("|".join(last))
    mirrored, count = re.subn(pattern, mirror, text, flags=re.S)
    assert count == len(last) and mirrored.count('<axis xyz="0 0 -1"/>') >= len(last)
    (tmp_path / "hand.urdf").write_text(mirrored)
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data["urdf"] = str(tmp_path / "hand.urdf")
    for joint in last:
        data["home"][joint] = -data["home"][joint]
    (tmp_path / "hand.yaml").write_text(yaml.safe_dump(data))
    original, flipped = gt.load_robot("hand").pads, gt.load_robot(tmp_path / "hand.yaml").pads
    for finger in ("index", "middle", "ring", "pinky"):
        np.testing.assert_allclose(flipped[finger].normal, original[finger].normal, atol=1e-9)
        np.testing.assert_allclose(flipped[finger].point, original[finger].point, atol=1e-9)
