"""Robot configs: every shipped config loads; bad configs are refused with a clear message."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import configs_dir
from graspnet_torch.robot import RobotCfg, available_robots, load_robot_cfg


def test_shipped_robots_are_listed():
    assert set(available_robots()) >= {"hand", "arm_hand", "manus"}


@pytest.mark.parametrize("name", ["hand", "arm_hand", "manus"])
def test_every_shipped_config_loads(name):
    cfg = load_robot_cfg(name)
    assert cfg.name == name and cfg.urdf.is_file()


def test_hand_palm_bounds_are_paper_table_1():
    b = load_robot_cfg("hand").palm_bounds
    d = math.pi / 180
    np.testing.assert_allclose(b.lower, [-0.1, -0.1, 0.15, -45 * d, -45 * d, -135 * d])
    np.testing.assert_allclose(b.upper, [0.1, 0.1, 0.25, 45 * d, 45 * d, -45 * d])
    assert b.to_degrees() == {"min": pytest.approx([-0.1, -0.1, 0.15, -45, -45, -135]),
                              "max": pytest.approx([0.1, 0.1, 0.25, 45, 45, -45])}


def _hand_yaml(tmp_path, **changes):
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    for key, value in changes.items():
        if value is None:
            data.pop(key)
        else:
            data[key] = value
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_unknown_robot_name():
    with pytest.raises(gt.ConfigError, match=r"unknown robot 'robonaut'.*hand"):
        gt.load_robot("robonaut")


def test_missing_urdf_file(tmp_path):
    with pytest.raises(gt.ConfigError, match=r"urdf: file not found: urdf/nope.urdf"):
        gt.load_robot(_hand_yaml(tmp_path, urdf="urdf/nope.urdf"))


def test_finger_link_not_in_urdf(tmp_path):
    fingers = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())["fingers"]
    fingers["index"] = {"base": "index_base", "tip": "index_nail"}
    with pytest.raises(gt.ConfigError, match=r"finger 'index' tip: link 'index_nail' is not in hand.urdf"):
        gt.load_robot(_hand_yaml(tmp_path, fingers=fingers))
    fingers["index"] = {"base": "index_root", "tip": "index_tip"}
    with pytest.raises(gt.ConfigError, match=r"finger 'index' base: link 'index_root'"):
        gt.load_robot(_hand_yaml(tmp_path, fingers=fingers))


def test_finger_tip_not_below_base(tmp_path):
    fingers = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())["fingers"]
    fingers["index"] = {"base": "index_base", "tip": "middle_tip"}
    with pytest.raises(gt.ConfigError, match=r"'middle_tip' is not below 'index_base'"):
        gt.load_robot(_hand_yaml(tmp_path, fingers=fingers))


def test_finger_base_must_be_rigid_on_palm(tmp_path):
    fingers = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())["fingers"]
    fingers["index"] = {"base": "index_proximal", "tip": "index_tip"}
    with pytest.raises(gt.ConfigError,
                       match=r"finger 'index': its chain must start at the palm, but joint 'index_abd' between "
                             r"palm_link 'palm' and base 'index_proximal' is revolute; set base to 'palm'"):
        gt.load_robot(_hand_yaml(tmp_path, fingers=fingers))


@pytest.mark.parametrize(
    ("bounds", "message"),
    [({"min": [0, 0, 0, 0, 0, 0], "max": [1, 1, 1, 1, 1, -1]}, "min > max for rz"),
     ({"min": [0, 0, 0, 0, 0], "max": [1, 1, 1, 1, 1, 1]}, r"palm_bounds.min: expected 6 numbers"),
     ({"min": [0, 0, 0, 0, 0, ".nan"], "max": [1, 1, 1, 1, 1, 1]}, "nan is not a finite number"),
     ({"low": [0] * 6, "max": [1] * 6}, "keys 'min' and 'max'")],
)
def test_bad_palm_bounds(tmp_path, bounds, message):
    if bounds.get("min") and bounds["min"][-1] == ".nan":
        bounds = {"min": [0, 0, 0, 0, 0, float("nan")], "max": bounds["max"]}
    with pytest.raises(gt.ConfigError, match=message):
        gt.load_robot(_hand_yaml(tmp_path, palm_bounds=bounds))


def test_unknown_key_and_missing_key(tmp_path):
    with pytest.raises(gt.ConfigError, match=r"unknown key.*palm_bound"):
        gt.load_robot(_hand_yaml(tmp_path, palm_bound={"min": [0] * 6, "max": [1] * 6}))
    with pytest.raises(gt.ConfigError, match=r"'palm_link' must be a non-empty string"):
        gt.load_robot(_hand_yaml(tmp_path, palm_link=None))


def test_hand_names_an_arms_free_hand(tmp_path):
    """``hand``: only beside an arm, a name or a file (a file relative to the config's folder)."""
    with pytest.raises(gt.ConfigError, match=r"'hand' \(a robot with an arm: its free hand, name or file\) got 'hand'"):
        load_robot_cfg(_hand_yaml(tmp_path, hand="hand"))
    data = yaml.safe_load((configs_dir() / "robot" / "arm_hand.yaml").read_text())
    for bad in (3, "", ["hand"]):
        with pytest.raises(gt.ConfigError, match=r"'hand' \(a robot with an arm"):
            RobotCfg.from_mapping({**data, "hand": bad}, "arm.yaml")
    folder = tmp_path / "arm"
    cfg = RobotCfg.from_mapping({**data, "hand": "my_hand.yaml"}, "arm.yaml", folder=folder)
    assert cfg.hand == str(folder / "my_hand.yaml") and load_robot_cfg("arm_hand").hand == "hand"


def test_malformed_yaml_names_the_file(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: hand\nfingers: [unclosed\n")
    with pytest.raises(gt.ConfigError, match=r"broken.yaml: malformed YAML \(line"):
        gt.load_robot(path)


@pytest.mark.parametrize(("defaults", "message"), [  # their values: tests/solver/test_defaults.py
    ({"noise": {"sigma": 0.1}}, r"'solver_defaults' must map srv, reward or solver to settings"),
    ({"solver": 3}, r"solver_defaults.solver: expected a mapping of settings"),
])
def test_bad_solver_defaults_are_refused(tmp_path, defaults, message):
    with pytest.raises(gt.ConfigError, match=message):
        gt.load_robot(_hand_yaml(tmp_path, solver_defaults=defaults))


def _installed_package(tmp_path, monkeypatch, name="fake_hand_description"):
    """A Python package on sys.path holding urdf/hand.urdf; importing it would fail (as
    robot_properties_fingers does without pinocchio), so resolving must not import it."""
    from graspnet_torch.paths import repo_root

    root = tmp_path / "site" / name
    (root / "urdf").mkdir(parents=True)
    (root / "__init__.py").write_text("raise ImportError('this package must not be imported')\n")
    (root / "urdf" / "hand.urdf").write_bytes((repo_root() / "urdf" / "hand" / "hand.urdf").read_bytes())
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    return root


def test_urdf_inside_an_installed_package(tmp_path, monkeypatch):
    root = _installed_package(tmp_path, monkeypatch)
    cfg = load_robot_cfg(_hand_yaml(tmp_path, urdf="package://fake_hand_description/urdf/hand.urdf"))
    assert cfg.urdf == (root / "urdf" / "hand.urdf").resolve()
    assert gt.load_robot(cfg).n_fingers == 5


@pytest.mark.parametrize(("urdf", "message"), [
    ("package://no_such_hand_pkg/urdf/hand.urdf",
     r"urdf: package://no_such_hand_pkg/urdf/hand.urdf: Python package 'no_such_hand_pkg' is not installed "
     r"\(pip install no-such-hand-pkg\)$"),
    ("package://fake_hand_description/urdf/nope.urdf",
     r"urdf: package://fake_hand_description/urdf/nope.urdf: no file 'urdf/nope.urdf' in package "
     r"'fake_hand_description' \(looked in .*fake_hand_description/urdf\)$"),
    ("package://fake_hand_description/../../robot.yaml",
     r"package://fake_hand_description/../../robot.yaml: '..' would lead out of package 'fake_hand_description'$"),
    ("package://fake_hand_description", r"expected package://<python package>/<path inside it>"),
    ("package:///urdf/hand.urdf", r"expected package://<python package>/<path inside it>"),
    ("package://fake_hand_description/urdf/%00.urdf", r"expected package://<python package>/<path inside it>"),
])
def test_bad_package_urdf_is_one_line(tmp_path, monkeypatch, urdf, message):
    _installed_package(tmp_path, monkeypatch)
    with pytest.raises(gt.ConfigError, match=message) as info:
        load_robot_cfg(_hand_yaml(tmp_path, urdf=urdf))
    assert "\n" not in str(info.value)


def test_a_link_out_of_the_package_is_refused(tmp_path, monkeypatch):
    root = _installed_package(tmp_path, monkeypatch)
    outside = tmp_path / "elsewhere" / "hand.urdf"
    outside.parent.mkdir()
    outside.write_bytes((root / "urdf" / "hand.urdf").read_bytes())
    (root / "urdf" / "linked.urdf").symlink_to(outside)
    data = yaml.safe_load(_hand_yaml(tmp_path).read_text())
    data["urdf"] = "package://fake_hand_description/urdf/linked.urdf"
    config = tmp_path / "configs" / "robot.yaml"  # its folder is not where the link leads
    config.parent.mkdir()
    config.write_text(yaml.safe_dump(data))
    with pytest.raises(gt.ConfigError, match=r"is outside the file's folder, the repository and installed packages"):
        load_robot_cfg(config)
