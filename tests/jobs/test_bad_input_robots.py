"""Bad robot files through the command line: a URDF this project cannot compute with (a cycle, a
joint with NaN or reversed limits, a zero axis, a NaN mimic multiplier, a NaN or infinite origin)
is refused in one line naming the file, the joint and the attribute, before any work and before
Hydra's run folder; a URDF's mesh outside the robot's folders is refused with the same line
whether or not a file is there."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.robot import available_robots, load_robot_cfg
from graspnet_torch.robot.geometry import link_shapes
from tests.mesh_robots import mesh_hand_urdf, write_box_mesh, write_robot
from tests.odd_hands import oddhand_urdf, write_oddhand
from tests.refusals import refused, refused_in_a_fresh_process, write_problem


def _odd_robot(tmp_path: Path, old: str, new: str) -> Path:
    """The odd hand (tests/odd_hands.py) with ``old`` replaced by ``new`` in its URDF: its YAML."""
    config = write_oddhand(tmp_path / "robot")
    text = oddhand_urdf()
    assert old in text, old
    (tmp_path / "robot" / "oddhand.urdf").write_text(text.replace(old, new, 1))
    return config


def _refused_by_training(tmp_path: Path, config: Path, message: str) -> str:
    line = refused(tmp_path, "train_fcnn.py", f"robot={config}", message=message)
    assert sorted(p.name for p in config.parent.iterdir()) == ["oddhand.urdf", "oddhand.yaml"]  # no export
    return line


URDF = "oddhand.urdf: joint "
THUMB_MOUNT = '<parent link="palm"/><child link="thumb_base"/>'
CYCLE = ('<parent link="thumb_tip"/><child link="thumb_base"/>',
         "joints 'thumb_mount', 'thumb_tip_joint', 'thumb_ip', 'thumb_mcp', 'thumb_flex', 'thumb_abd' form a cycle: "
         "link 'thumb_base' is its own ancestor (thumb_base <- thumb_tip <- thumb_l4 <- thumb_l3")


# ------------------------------------------------------------------ the URDF's kinematics
@pytest.mark.parametrize(("old", "new", "message"), [
    (THUMB_MOUNT, CYCLE[0], CYCLE[1]),  # the thumb hangs from its own tip
    ('<joint name="thumb_tip_joint" type="fixed"><parent link="thumb_l4"/><child link="thumb_tip"/>',
     '<joint name="loop" type="fixed"><parent link="thumb_tip"/><child link="thumb_base"/></joint>'
     '<joint name="thumb_tip_joint" type="fixed"><parent link="thumb_l4"/><child link="thumb_tip"/>',
     "link 'thumb_base' is the child of two joints, 'thumb_mount' and 'loop'"),
    ('lower="0.0" upper="1.2"', 'lower="1.2" upper="0.0"', URDF + "'thumb_mcp' <limit>: lower=1.2 > upper=0"),
    ('lower="0.0" upper="1.2"', 'lower="nan" upper="1.2"',
     URDF + "'thumb_mcp' <limit> lower=nan: expected a finite number"),
    ('lower="0.0" upper="1.2"', 'lower="0.0" upper="inf"',
     URDF + "'thumb_mcp' <limit> upper=inf: expected a finite number"),
    ('axis xyz="1 1 0"', 'axis xyz="0 0 0"',
     URDF + "'thumb_flex' <axis> xyz=[0.0, 0.0, 0.0]: expected a direction (3 finite numbers"),
    ('axis xyz="1 1 0"', 'axis xyz="1 nan 0"', URDF + "'thumb_flex' <axis> xyz=[1.0, nan, 0.0]"),
    ('multiplier="0.7"', 'multiplier="nan"', URDF + "'index_dip' <mimic> multiplier=nan: expected a finite number"),
    ('<mimic joint="index_pip"', '<mimic joint="index_nope"',
     URDF + "'index_dip' <mimic> joint='index_nope' is not a joint of the file"),
    ('<origin xyz="0 0 0.04" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="0.0" upper="1.2"',
     '<origin xyz="0 nan 0.04" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="0.0" upper="1.2"',
     URDF + "'thumb_mcp' <origin> xyz=[0.0, nan, 0.04]: expected finite numbers within +-100 m"),
    ('rpy="0.3 -0.4 0.6"', 'rpy="0.3 nan 0.6"', URDF + "'thumb_mount' <origin> rpy=[0.3, nan, 0.6]"),
    ('xyz="0.03 0.015 0.02"', 'xyz="0.03 nan 0.02"', URDF + "'thumb_mount' <origin> xyz=[0.03, nan, 0.02]"),
    ('xyz="0.03 0.015 0.02"', 'xyz="0.03 inf 0.02"', URDF + "'thumb_mount' <origin> xyz=[0.03, inf, 0.02]"),
    ('xyz="0.03 0.015 0.02"', 'xyz="0.03 1e300 0.02"', URDF + "'thumb_mount' <origin> xyz=[0.03, 1e+300, 0.02]"),
    ('name="thumb_ip" type="revolute"', 'name="thumb_ip" type="floating"',
     URDF + "'thumb_ip' type='floating': not supported"),
    ('<parent link="thumb_l3"/>', '<parent link="thumb_l9"/>',
     URDF + "'thumb_ip' <parent> link 'thumb_l9' is not a link of the file"),
    ('name="thumb_ip"', 'name="thumb_mcp"', URDF + "'thumb_mcp' is defined twice"),
    ('lower="0.0" upper="1.2"', 'lower="0.5" upper="0.5"',
     "finger 'thumb': joint 'thumb_mcp' cannot move (its <limit> range"),
    ('box size="0.07 0.02 0.08"', 'box size="0.07 nan 0.08"',
     "oddhand.urdf: link 'palm' <collision> size=[0.07, nan, 0.08]: expected finite numbers"),
    ('radius="0.006"', 'radius="-0.006"', "link 'thumb_base' <collision> radius=-0.006: expected sizes >= 0"),
], ids=["cycle", "two-parents", "lower>upper", "nan-limit", "inf-limit", "zero-axis", "nan-axis", "nan-mimic",
        "unknown-mimic", "nan-origin", "nan-rpy", "nan-base", "inf-base", "huge-base", "floating", "unknown-link",
        "twice", "stuck-joint", "nan-box", "negative-radius"])
def test_a_bad_urdf_is_refused_by_training_before_any_folder(tmp_path, old, new, message):
    line = _refused_by_training(tmp_path, _odd_robot(tmp_path, old, new), message)
    assert str(tmp_path / "robot") in line  # the file, by its path


@pytest.mark.parametrize(("value", "shown"), [("nan", "nan"), ("inf", "inf"), ("-inf", "-inf")])
def test_a_finger_base_with_a_non_finite_origin_is_refused_by_the_solver(tmp_path, value, shown):
    """The reported case: the search ran and ended in 'internal error: result not finite'."""
    config = _odd_robot(tmp_path, 'xyz="0.03 0.015 0.02"', f'xyz="0.03 {value} 0.02"')
    problem = write_problem(tmp_path, "robot: oddhand\ncontacts:\n  - {finger: thumb, position: [0.02, 0, 0.15]}\n"
                                      "  - {finger: index, position: [-0.02, 0, 0.15]}\n")
    out = tmp_path / "r.json"
    refused(tmp_path, "solve_grasp.py", f"robot={config}", f"problem={problem}", f"out={out}",
            message=f"oddhand.urdf: joint 'thumb_mount' <origin> xyz=[0.03, {shown}, 0.02]: expected finite numbers")
    assert not out.exists()


def test_a_cycle_is_refused_at_once_and_small_in_a_fresh_process(tmp_path):
    """A link that is its own ancestor: before, walking up the tree never ended (past 4 GB)."""
    config = _odd_robot(tmp_path, THUMB_MOUNT, CYCLE[0])
    refused_in_a_fresh_process(tmp_path, "train_fcnn.py", f"robot={config}", message=CYCLE[1], max_bytes=2 << 30)


def _with_extra(tmp_path: Path, extra: str) -> Path:
    config = write_oddhand(tmp_path / "robot")
    (tmp_path / "robot" / "oddhand.urdf").write_text(oddhand_urdf().replace("</robot>", extra + "</robot>"))
    return config


def test_a_chain_too_deep_for_the_kinematics_is_refused(tmp_path):
    """pytorch-kinematics builds its tree recursively: 200 joints deep was a RecursionError."""
    links = "".join(f'<link name="x{i}"/>' for i in range(200))
    joints = "".join(f'<joint name="x{i}" type="fixed"><parent link="{f"x{i - 1}" if i else "palm"}"/>'
                     f'<child link="x{i}"/></joint>' for i in range(200))
    chain = links + joints
    _refused_by_training(tmp_path, _with_extra(tmp_path, chain), "link 'x64' is 65 joints below its root link; "
                                                                 "at most 64 are supported")


def test_a_urdf_of_too_many_links_is_refused_before_the_tree_is_built(tmp_path):
    """Building the tree takes time quadratic in its links (30,000: about 3 minutes)."""
    links = "".join(f'<link name="w{i}"/><joint name="w{i}" type="fixed"><parent link="palm"/><child link="w{i}"/>'
                    f'</joint>' for i in range(1000))
    _refused_by_training(tmp_path, _with_extra(tmp_path, links), "1019 links; at most 1000 are supported")


def test_the_shipped_and_example_robots_pass_the_checks():
    for name in (*available_robots(), "examples/trifinger/trifinger.yaml"):
        try:
            cfg = load_robot_cfg(name)
        except gt.ConfigError as exc:  # an example whose URDF comes with an optional package
            assert "is not installed" in str(exc) or "file not found" in str(exc), exc
            continue
        gt.Robot(cfg)


# ------------------------------------------------------------------ the URDF's meshes
def _mesh_robot(tmp_path: Path, filename: str) -> Path:
    return write_robot(tmp_path / "robot", mesh_hand_urdf(f'<mesh filename="{filename}"/>'))


def _solve_with_an_object(tmp_path: Path, config: Path, *args: str, message: str) -> str:
    """solve_grasp.py with an object to collide with: every collision mesh is loaded before any work."""
    problem = tmp_path / "p.yaml"
    problem.write_text(yaml.safe_dump({
        "robot": "meshhand", "object": {"shape": "box", "size": [0.04, 0.04, 0.04], "pose": [0, 0, 0.1, 0, 0, 0]},
        "contacts": [{"finger": "thumb", "position": [0.02, 0, 0]}, {"finger": "index", "position": [-0.02, 0, 0]}]}))
    out = tmp_path / "r.json"
    line = refused(tmp_path, "solve_grasp.py", f"robot={config}", f"problem={problem}", f"out={out}", *args,
                   message=message)
    assert not out.exists()
    return line


OUTSIDE = "is outside the URDF's folder, the robot config's folder, the repository and installed packages; " \
          "set allow_outside_paths=true to use it"


@pytest.mark.parametrize("form", ["{path}", "file://{path}", "../elsewhere/{name}"])
def test_a_mesh_outside_the_robots_folders_gets_one_message_whether_or_not_it_exists(tmp_path, form):
    there = write_box_mesh(tmp_path / "elsewhere" / "palm.stl")
    lines = []
    for name in ("palm.stl", "missing.stl"):
        uri = form.format(path=there.parent / name, name=name)
        config = _mesh_robot(tmp_path, uri)
        lines.append(_solve_with_an_object(tmp_path, config, message=f"link 'palm' collision: mesh '{uri}' {OUTSIDE}"))
    assert lines[0].replace("palm.stl", "missing.stl") == lines[1]


def test_a_link_to_a_mesh_outside_is_refused_like_the_mesh(tmp_path):
    there = write_box_mesh(tmp_path / "elsewhere" / "palm.stl")
    config = _mesh_robot(tmp_path, "meshes/palm.stl")
    (tmp_path / "robot" / "meshes").mkdir()
    (tmp_path / "robot" / "meshes" / "palm.stl").symlink_to(there)
    _solve_with_an_object(tmp_path, config, message=f"mesh 'meshes/palm.stl' {OUTSIDE}")


def test_meshes_inside_the_robots_folders_still_load(tmp_path, monkeypatch):
    """Beside the URDF, beside the robot config (the URDF one folder down), in the folder
    ``<pkg>`` holding the URDF's folder (package://), and anywhere with allow_outside_paths."""
    write_box_mesh(tmp_path / "hand" / "meshes" / "palm.stl")
    write_box_mesh(tmp_path / "elsewhere" / "palm.stl")
    urdfs = {"beside.urdf": "meshes/palm.stl", "urdf/down.urdf": "../meshes/palm.stl",
             "urdf/package.urdf": "package://hand/meshes/palm.stl"}
    for rel, uri in urdfs.items():
        (tmp_path / "hand" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "hand" / rel).write_text(mesh_hand_urdf(f'<mesh filename="{uri}"/>'))
    for rel in urdfs:
        config = write_robot(tmp_path / "hand", (tmp_path / "hand" / rel).read_text(), name="meshhand")
        data = yaml.safe_load(config.read_text())
        config.write_text(yaml.safe_dump({**data, "urdf": rel}))
        palm = [s for s in link_shapes(gt.load_robot(config).urdf) if s.link == "palm"]
        assert palm and palm[0].kind == "mesh", rel
    outside = _mesh_robot(tmp_path, str(tmp_path / "elsewhere" / "palm.stl"))
    with pytest.raises(gt.ConfigError, match="is outside the URDF's folder"):
        link_shapes(gt.load_robot(outside).urdf)
    robot = gt.Robot(load_robot_cfg(outside, allow_outside_paths=True))
    assert [s.kind for s in link_shapes(robot.urdf) if s.link == "palm"] == ["mesh"]
