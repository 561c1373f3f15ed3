"""A third-party hand end to end: the TriFinger Pro of the PyPI package robot-properties-fingers
(BSD-3), named by ``package://`` in the example config. Train its FCNN briefly through the job,
solve random reachable problems, and check every result from the URDF alone (pytorch-kinematics,
float64); then the command line on the example cube problem."""

from __future__ import annotations

import importlib.util
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.fcnn import load_finger_ik
from graspnet_torch.paths import repo_root
from graspnet_torch.robot import load_robot_cfg
from tests.in_process import run_script

PACKAGE = "robot_properties_fingers"  # not imported: its __init__ imports pinocchio
EXAMPLE = repo_root() / "examples" / "trifinger"


def _package_root() -> Path | None:
    try:
        spec = importlib.util.find_spec(PACKAGE)
    except (ImportError, ValueError):
        return None
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    return Path(locations[0]) if locations else None


pytestmark = pytest.mark.skipif(
    _package_root() is None or not (_package_root() / "urdf" / "pro" / "trifingerpro.urdf").is_file(),
    reason=f"the TriFinger URDF needs the '{PACKAGE}' package (pip install robot-properties-fingers, in the dev extra)")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """The example config and cube problem copied into a temporary folder, its FCNN trained
    briefly through the training job (exported beside the config): (folder, robot, ik, rows).
    About 15 s on one thread."""
    from graspnet_torch.jobs.train_fcnn import train_fcnn_job

    folder = tmp_path_factory.mktemp("trifinger")
    shutil.copy(EXAMPLE / "trifinger.yaml", folder / "trifinger.yaml")
    shutil.copy(EXAMPLE / "cube.yaml", folder / "cube.yaml")
    config = folder / "trifinger.yaml"
    fcnn = {"epochs": 30, "targets_per_epoch": 128, "train_steps": 20, "val_targets": 500, "val_every": 10}
    threads = torch.get_num_threads()
    try:  # the job sets one torch thread; the solves keep it (several spin-waiting threads crawl on a busy machine)
        ik, rows = train_fcnn_job({"robot": str(config), "fcnn": fcnn, "eval_targets": 2000, "progress": False},
                                  folder / "run")
        yield folder, ik.robot, ik, rows
    finally:
        torch.set_num_threads(threads)


def test_example_config_names_the_packaged_urdf():
    cfg = load_robot_cfg(EXAMPLE / "trifinger.yaml")
    data = yaml.safe_load((EXAMPLE / "trifinger.yaml").read_text())
    assert data["urdf"] == "package://robot_properties_fingers/urdf/pro/trifingerpro.urdf"
    assert cfg.urdf == (_package_root() / "urdf" / "pro" / "trifingerpro.urdf").resolve()
    assert list(cfg.fingers) == ["f0", "f120", "f240"]
    assert cfg.checkpoint == EXAMPLE.resolve() / "trifinger.fcnn.pt"


@pytest.mark.slow
def test_training_exports_the_checkpoint_beside_the_config(trained):
    folder, robot, ik, rows = trained
    assert (folder / "trifinger.fcnn.pt").is_file() and (folder / "run" / "state.pt").is_file()
    assert robot.cfg.checkpoint == (folder / "trifinger.fcnn.pt").resolve()
    assert [r["finger"] for r in rows] == ["f0", "f120", "f240"] and all(r["within_limits"] for r in rows)
    loaded = load_finger_ik(robot)
    assert loaded.finger_names == ik.finger_names == ("f0", "f120", "f240")


def _rpy(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rz(rz) Ry(ry) Rx(rx), radians."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    return (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
            @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))


def _tips_from_urdf(urdf: bytes, palm_link: str, tips: dict[str, str], result: dict) -> dict[str, np.ndarray]:
    """World fingertip positions of a result, from the URDF and the result's numbers only: the
    finger's joints are the movable joints from ``palm_link`` to its tip link (chain order), the
    world is the URDF root placed so that ``palm_link`` has the reported ``palm_pose``."""
    import pytorch_kinematics as pk

    chain = pk.build_chain_from_urdf(urdf).to(dtype=torch.float64)
    values = {}
    for finger, tip in tips.items():
        names = pk.SerialChain(chain, tip, palm_link).get_joint_parameter_names()
        assert len(names) == len(result["joints"][finger]), finger
        values.update({n: math.radians(v) for n, v in zip(names, result["joints"][finger], strict=True)})
    order = chain.get_joint_parameter_names()
    frames = chain.forward_kinematics(torch.tensor([[values.get(n, 0.0) for n in order]], dtype=torch.float64))
    palm = np.eye(4)
    x, y, z, rx, ry, rz = result["palm_pose"]
    palm[:3, :3], palm[:3, 3] = _rpy(*np.radians([rx, ry, rz])), [x, y, z]
    world = palm @ np.linalg.inv(frames[palm_link].get_matrix()[0].numpy())
    return {f: (world @ frames[tip].get_matrix()[0].numpy())[:3, 3] for f, tip in tips.items()}


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.slow
def test_random_reachable_problems_are_solved_and_check_from_the_urdf(trained, seed):
    _folder, robot, ik, _rows = trained
    problem = gt.random_reachable_problem(robot, seed, n_fingers=(2, 3))
    result = gt.solve(problem, trials=10, seed=0, solver={"polish": {"mode": "whole"}}, robot=robot, finger_ik=ik)
    data = json.loads(result.to_json())
    assert data["total_error_mm"] < 1.0, data["fingertip_error_mm"]
    tips = {f: robot.cfg.fingers[f].tip for f in robot.finger_names}
    world = _tips_from_urdf(robot.cfg.urdf.read_bytes(), robot.cfg.palm_link, tips, data)
    contacts = problem.contacts_world()
    assert set(data["fingertip_error_mm"]) == set(problem.fingers)
    for k, finger in enumerate(problem.fingers):
        error_m = float(np.linalg.norm(world[finger] - np.asarray(contacts[k], dtype=np.float64)))
        assert abs(error_m - data["fingertip_error_mm"][finger] / 1000) < 1e-6, finger
    assert sum(data["fingertip_error_mm"].values()) == pytest.approx(data["total_error_mm"], abs=1e-6)


@pytest.mark.slow
def test_cli_solves_the_cube_problem(trained):
    folder = trained[0]
    out = folder / "r.json"
    res = run_script("solve_grasp.py", f"robot={folder / 'trifinger.yaml'}", f"problem={folder / 'cube.yaml'}",
                     "trials=4", "max_iterations=50", "pictures=false", "tensorboard=false", f"out={out}",
                     f"hydra.run.dir={folder / 'cli'}")
    assert res.returncode == 0, res.stderr
    data = json.loads(out.read_text())
    assert data["robot"] == "trifinger" and set(data["joints"]) == {"f0", "f120", "f240"}
    assert set(data["fingertip_error_mm"]) == {"f0", "f120", "f240"} and len(data["trials"]) == 4
    assert "Unknown attribute" not in res.stderr  # the vendor's extra inertia attributes are not reported
