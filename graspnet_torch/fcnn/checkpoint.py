"""FCNN checkpoints: trained expert sets of a robot's fingers, one file per robot.

The file (``torch.save`` of plain dicts and tensors, loaded with ``weights_only=True``) records for
each finger the chain it was trained for (joint names and a fingerprint of its geometry and
limits): loading it for a robot whose finger differs is refused with a clear error, as is a
corrupted file. Files are written atomically.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspnet_torch.errors import CheckpointError
from graspnet_torch.fcnn.experts import ExpertSet, ExpertSetCfg
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.io import atomic_path
from graspnet_torch.paths import checkpoints_dir
from graspnet_torch.robot.chain import ChainSpec
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.fingers import FingerChain
from graspnet_torch.robot.robot import Robot, load_robot

__all__ = ["FORMAT", "chain_fingerprint", "default_checkpoint", "finger_ik_of", "load_finger_ik", "load_payload",
           "non_finite_tensors", "robot_checkpoint", "save_finger_ik"]

FORMAT = "graspnet_torch.fcnn/1"


def chain_fingerprint(chain: ChainSpec | FingerChain) -> str:
    """A hash of what a finger's inverse kinematics depends on: joint types, axes, fixed
    transforms (tip offset included) and limits (rounded to 1e-9), and the mimic couplings of a
    finger that has any (a finger without is hashed as its plain chain, as before mimic support)."""
    spec = chain.spec if isinstance(chain, FingerChain) else chain
    h = hashlib.sha256()
    h.update(",".join(spec.joint_types).encode())
    for arr in (spec.axes, spec.offsets, spec.lower, spec.upper):
        h.update(np.round(np.asarray(arr, dtype=np.float64), 9).tobytes())
    if isinstance(chain, FingerChain) and not chain.identity:
        for arr in (chain.coupling, chain.coupling_offset, chain.lower, chain.upper):
            h.update(np.round(np.asarray(arr, dtype=np.float64), 9).tobytes())
    return h.hexdigest()[:16]


def non_finite_tensors(obj: Any, prefix: str = "") -> list[str]:
    """Dotted paths of the floating tensors in a nested dict/list that hold NaN or infinity."""
    if isinstance(obj, torch.Tensor):
        return [prefix] if obj.is_floating_point() and not bool(torch.isfinite(obj).all()) else []
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in non_finite_tensors(v, f"{prefix}.{k}" if prefix else str(k))]
    if isinstance(obj, list | tuple):
        return [p for i, v in enumerate(obj) for p in non_finite_tensors(v, f"{prefix}[{i}]")]
    return []


def load_payload(path: str | Path, fmt: str, unreadable: str, foreign: str) -> dict:
    """A file of plain dicts and tensors (``torch.load`` with ``weights_only=True``) that says it
    is of format ``fmt``. Raises :class:`CheckpointError` "<path>: <unreadable> (<error type>)"
    when torch cannot read it (it raises assorted errors on truncated or foreign files), and
    "<path>: <foreign>" when it is not a dict of that format."""
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise CheckpointError(f"{path}: {unreadable} ({type(exc).__name__})") from None
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise CheckpointError(f"{path}: {foreign}")
    return payload


def default_checkpoint(robot_name: str) -> Path:
    return checkpoints_dir() / robot_name / "fcnn.pt"


def robot_checkpoint(robot: Robot | RobotCfg) -> Path:
    """Where a robot's FCNN is read from (and written by ``train_fcnn.py``): its config's
    ``checkpoint``, else ``<config folder>/<name>.fcnn.pt`` for a config given by path, else
    ``checkpoints/<name>/fcnn.pt``."""
    cfg = robot.cfg if isinstance(robot, Robot) else robot
    return cfg.checkpoint or default_checkpoint(cfg.name)


def _train_hint(robot: Robot) -> str:
    return f"`python scripts/train_fcnn.py robot={robot.cfg.cli_name}`"


def save_finger_ik(ik: FingerIK, path: str | Path, info: dict | None = None) -> Path:
    """Write ``ik``'s experts (active ones only) to ``path`` atomically."""
    fingers = {}
    for name, experts in ik.experts.items():
        E = experts.n_active
        state = {k: v[:E].detach().cpu().clone() if k in ("W1", "b1", "W2", "b2", "W3", "b3", "rep_postures")
                 else v.detach().cpu().clone() for k, v in experts.state_dict().items() if k != "active"}
        chain = ik.robot.fingers[name].chain
        fingers[name] = {"state": state, "n_experts": E, "hidden": experts.cfg.hidden,
                         "max_experts": experts.cfg.max_experts, "joint_names": list(chain.joint_names),
                         "fingerprint": chain_fingerprint(chain)}
    payload = {"format": FORMAT, "robot": ik.robot.name, "fingers": fingers, "info": info or {}}
    with atomic_path(path, suffix=".pt") as tmp:
        torch.save(payload, tmp)
    return Path(path)


def _experts_from(entry: dict, robot: Robot, finger: str, where: str) -> ExpertSet:
    chain = robot.fingers[finger].chain
    if list(entry["joint_names"]) != list(chain.joint_names) or entry["fingerprint"] != chain_fingerprint(chain):
        raise CheckpointError(f"{where}: finger '{finger}' was trained for a different chain than robot "
                              f"'{robot.name}' has now (URDF or limits changed?); retrain with "
                              f"{_train_hint(robot)}")
    E, n = int(entry["n_experts"]), chain.n_joints
    state = entry["state"]
    bad = non_finite_tensors(state)
    if bad:
        raise CheckpointError(f"{where}: finger '{finger}': non-finite values (NaN or infinity) in "
                              f"{', '.join(bad[:3])}; retrain with {_train_hint(robot)}")
    if not bool((state["x_scale"] > 0).all()) or not bool((state["q_upper"] >= state["q_lower"]).all()):
        raise CheckpointError(f"{where}: finger '{finger}': input scales must be positive and joint ranges "
                              f"non-empty; the file is corrupted")
    cfg = ExpertSetCfg(hidden=int(entry["hidden"]), max_experts=max(int(entry["max_experts"]), E))
    experts = ExpertSet(n, state["x_center"], state["x_scale"], state["q_lower"], state["q_upper"], cfg)
    full = experts.state_dict()
    for key in ("W1", "b1", "W2", "b2", "W3", "b3", "rep_postures"):
        if tuple(state[key].shape[1:]) != tuple(full[key].shape[1:]) or state[key].shape[0] != E:
            want = (E, *full[key].shape[1:])
            raise CheckpointError(f"{where}: finger '{finger}': tensor '{key}' has shape "
                                  f"{tuple(state[key].shape)}, expected {want}")
        full[key][:E] = state[key]
    full["active"][:E] = True
    for key in ("x_center", "x_scale", "q_lower", "q_upper"):
        full[key] = state[key]
    experts.load_state_dict(full)
    return experts


def finger_ik_of(robot: Robot) -> FingerIK | None:
    """A robot's trained finger IK (:func:`load_finger_ik`), or None for a robot without fingers."""
    return load_finger_ik(robot) if robot.n_fingers else None


def load_finger_ik(robot: str | Robot = "hand", path: str | Path | None = None) -> FingerIK:
    """Trained finger IK of a robot: ``path``, else the robot config's ``checkpoint`` (which may
    be another robot's with the same finger chains: every finger's chain fingerprint must match),
    else ``checkpoints/<robot>/fcnn.pt``.

    Raises:
        CheckpointError: missing, corrupted or mismatched checkpoint (the message names the file).
    """
    robot = robot if isinstance(robot, Robot) else load_robot(robot)
    shared = path is None and robot.cfg.checkpoint is not None  # the robot config names another robot's file
    path = Path(path) if path is not None else robot_checkpoint(robot)
    where = str(path)
    if not path.is_file():
        raise CheckpointError(f"{where}: FCNN checkpoint not found; train one with "
                              f"{_train_hint(robot)}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises assorted errors on truncated or foreign files
        raise CheckpointError(f"{where}: not a readable checkpoint ({type(exc).__name__})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise CheckpointError(f"{where}: not an FCNN checkpoint (format {found!r}, expected {FORMAT!r})")
    if payload.get("robot") != robot.name and not shared:
        raise CheckpointError(f"{where}: trained for robot '{payload.get('robot')}', not '{robot.name}'")
    try:
        fingers = payload["fingers"]
        unknown = [f for f in fingers if f not in robot.fingers]
        if unknown:
            raise CheckpointError(f"{where}: fingers {unknown} are not fingers of robot '{robot.name}'")
        experts = {f: _experts_from(fingers[f], robot, f, where) for f in robot.finger_names if f in fingers}
    except (KeyError, TypeError, RuntimeError) as exc:
        raise CheckpointError(f"{where}: malformed checkpoint ({type(exc).__name__}: {exc})") from None
    if not experts:
        raise CheckpointError(f"{where}: holds no finger of robot '{robot.name}'")
    return FingerIK(robot, experts)
