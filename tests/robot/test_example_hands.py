"""Every example robot config (examples/*/*.yaml with a `urdf:` key; a new folder is tested without
touching this file): it loads with ``graspnet_torch.load_robot``, every finger's fingertip from the
project's kinematics (``Robot.fingertips_palm``) agrees with pytorch-kinematics on the whole URDF to
1e-9 m at random joint values within the limits (float64), and every finger has a pad with a unit
normal, derived from the URDF's collision geometry where the config gives none.

The oracle is pytorch-kinematics' chain built with its origins in float64
(tests/robot/test_link_frames.pk_chain64): its parser rounds origins and axes to float32, ~1e-8 m
off on these hands' fractional millimetres, which a 1e-9 m check would read as a kinematics error.

Skipped, with the reason: a config whose URDF the user fetches (scripts/fetch_hands.py: schunk_svh,
ability_hand, inspire_hand, icub_hand, not shipped) until it is there, and a config whose URDF is in a Python
package that is not installed."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import repo_root
from tests.robot.test_link_frames import oracle_joints, pk_chain64, random_joints

EXAMPLES = repo_root() / "examples"
FETCHED = {  # config file name -> why its URDF is not in a fresh clone
    "schunk_svh_right.yaml": "its URDF (dex-urdf, GPL-3.0) is fetched by the user, not shipped: "
                             "run scripts/fetch_hands.py",
    "ability_hand_right.yaml": "its URDF (dex-urdf; a licence that grants no redistribution) is fetched by the "
                               "user, not shipped: run scripts/fetch_hands.py",
    "inspire_hand_right.yaml": "its URDF (dex-urdf; a licence that grants no redistribution) is fetched by the "
                               "user, not shipped: run scripts/fetch_hands.py",
    "icub_hand_left.yaml": "its URDF (icub-models, CC BY-SA 4.0) is copied by the user from the installed package, "
                           "not shipped: run scripts/fetch_hands.py",
}


def robot_configs() -> list[Path]:
    """The example YAML files that are robot configs (a problem file, e.g. trifinger/cube.yaml, has no `urdf`)."""
    out = []
    for path in sorted(EXAMPLES.glob("*/*.yaml")):
        data = yaml.safe_load(path.read_text())
        if isinstance(data, dict) and "urdf" in data:
            out.append(path)
    return out


def _param(path: Path):
    urdf = str(yaml.safe_load(path.read_text())["urdf"])
    reason = None
    if path.name in FETCHED and not (path.parent / urdf).is_file():
        reason = FETCHED[path.name]
    elif urdf.startswith("package://"):
        package = urdf.removeprefix("package://").split("/", 1)[0]
        if importlib.util.find_spec(package) is None:
            reason = f"its URDF is in the Python package '{package}', not installed here (the config says how)"
    marks = [pytest.mark.skip(reason=reason)] if reason else []
    return pytest.param(path, id=f"{path.parent.name}/{path.stem}", marks=marks)


CONFIGS = [_param(path) for path in robot_configs()]
_LOADED: dict[Path, gt.Robot] = {}


def _robot(path: Path) -> gt.Robot:
    if path not in _LOADED:
        _LOADED[path] = gt.load_robot(path)
    return _LOADED[path]


def test_the_examples_are_found():
    names = {path.parent.name for path in robot_configs()}
    assert {"allegro_hand", "leap_hand", "barrett_hand", "dclaw_gripper", "shadow_hand", "trifinger",
            "dexmate_f5d6", "schunk_svh"} <= names


@pytest.mark.parametrize("path", CONFIGS)
def test_fingertips_match_pytorch_kinematics(path, gen):
    robot = _robot(path)
    assert robot.fingers, f"{path}: no fingers"
    _, q, _, shared = random_joints(robot, 8, gen)
    lo, hi = (torch.as_tensor(a, dtype=torch.float64) for a in robot.finger_limits)
    assert torch.all((q >= lo) & (q <= hi))
    tips = robot.fingertips_palm(q, shared).numpy()

    chain = pk_chain64(robot.urdf.path.read_bytes())
    frames = chain.forward_kinematics(oracle_joints(robot, chain.get_joint_parameter_names(), None, q, shared))
    palm = frames[robot.cfg.palm_link].get_matrix()
    for k, (name, cfg) in enumerate(robot.cfg.fingers.items()):
        T = torch.linalg.solve(palm, frames[cfg.tip].get_matrix())
        offset = torch.tensor([*(cfg.tip_offset or (0.0, 0.0, 0.0)), 1.0], dtype=torch.float64)
        want = (T @ offset)[:, :3].numpy()
        np.testing.assert_allclose(tips[:, k], want, atol=1e-9, rtol=0, err_msg=f"{path.name}: finger {name}")


@pytest.mark.parametrize("path", CONFIGS)
def test_every_finger_has_a_pad(path):
    robot = _robot(path)
    pads = robot.pads
    assert list(pads) == list(robot.finger_names)
    for name, pad in pads.items():
        assert np.all(np.isfinite(pad.point)), name
        assert np.linalg.norm(pad.normal) == pytest.approx(1.0, abs=1e-12), name
        cfg = robot.cfg.fingers[name]
        if cfg.pad is None:  # derived: on the tip link or a link rigidly above it, with collision geometry
            robot.urdf.fixed_transform(pad.link, cfg.tip, f"{name}'s pad")  # raises unless rigidly above the tip
            assert robot.urdf.links[pad.link].collisions, f"{name}: pad on {pad.link}, which has no collision geometry"
            assert abs(pad.depth) < 0.1, name  # within 10 cm of the tip frame
