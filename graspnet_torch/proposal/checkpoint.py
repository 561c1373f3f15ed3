"""Posture proposal checkpoints, beside the FCNN's: ``checkpoints/<robot>/posture.pt``, or
``<folder>/<name>.posture.pt`` beside a robot config given by path.

The file (``torch.save`` of plain dicts and tensors, loaded with ``weights_only=True``) records
what the model was trained for (the robot's name and kind, its search variables and target
slots, its finger or body joint names): loading it for a robot that differs, or a corrupted file,
is refused with a clear error naming the file. Files are written atomically.
"""

from __future__ import annotations

from pathlib import Path

import torch

from graspnet_torch.errors import CheckpointError, ConfigError
from graspnet_torch.fcnn.checkpoint import load_payload, non_finite_tensors
from graspnet_torch.io import atomic_path
from graspnet_torch.paths import checkpoints_dir
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import build, check_value, clip

__all__ = ["FORMAT", "load_proposal", "posture_checkpoint", "proposal_of", "robot_signature", "save_proposal"]

FORMAT = "graspnet_torch.posture/1"
MAX_SIZE = 10_000  # target slots or search variables a file may declare (robots have up to tens)


def posture_checkpoint(robot: Robot) -> Path:
    """Where a robot's proposal model is read from (and written by ``train_posture.py``):
    ``<config folder>/<name>.posture.pt`` for a robot config given by its path (beside its FCNN),
    else ``checkpoints/<name>/posture.pt``."""
    cfg = robot.cfg
    if cfg.cli_name != cfg.name:  # a config file of its own, not a shipped one
        return Path(cfg.source).resolve().parent / f"{cfg.name}.posture.pt"
    return checkpoints_dir() / cfg.name / "posture.pt"


def robot_signature(robot: Robot) -> dict:
    """What a proposal model depends on: the robot's kind, the joints of its search variables and
    its target slots (finger names, or a gripper's two points)."""
    return {"kind": robot.kind, "fingers": list(robot.finger_names), "body_joints": list(robot.body_joint_names)}


def _train_hint(robot: Robot) -> str:
    return f"`python scripts/train_posture.py robot={robot.cfg.cli_name}`"


def save_proposal(model: PostureProposal, robot: Robot, cfg: ProposalCfg, path: str | Path,
                  info: dict | None = None) -> Path:
    """Write the model to ``path`` atomically."""
    payload = {"format": FORMAT, "robot": robot.name, "signature": robot_signature(robot), "slots": model.slots,
               "n": model.n, "heads": cfg.heads, "hidden": list(cfg.hidden),
               "state": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}, "info": info or {}}
    with atomic_path(Path(path), suffix=".pt") as tmp:
        torch.save(payload, tmp)
    return Path(path)


def load_proposal(robot: Robot, path: str | Path | None = None) -> PostureProposal:
    """A robot's trained proposal model: ``path``, else :func:`posture_checkpoint`.

    Raises:
        CheckpointError: missing, corrupted or trained for another robot (the message names the file).
    """
    path = Path(path) if path is not None else posture_checkpoint(robot)
    where = str(path)
    if not path.is_file():
        raise CheckpointError(f"{where}: no posture proposal model for robot '{robot.name}'; train one with "
                              f"{_train_hint(robot)}")
    payload = load_payload(path, FORMAT, "not a readable posture proposal checkpoint",
                           f"not a posture proposal checkpoint (format {FORMAT!r} expected)")
    try:
        signature, state = payload["signature"], payload["state"]
        sizes = {key: payload[key] for key in ("slots", "n", "heads", "hidden")}
    except KeyError as exc:
        raise CheckpointError(f"{where}: malformed posture proposal checkpoint (no {exc})") from None
    slots, n, cfg = _declared_sizes(sizes, where)
    if not isinstance(signature, dict) or not isinstance(state, dict):
        raise CheckpointError(f"{where}: malformed posture proposal checkpoint (signature, state)")
    if payload.get("robot") != robot.name or signature != robot_signature(robot):
        raise CheckpointError(f"{where}: trained for robot '{payload.get('robot')}' ({signature.get('kind')}), "
                              f"not for robot '{robot.name}' as it is now; retrain with {_train_hint(robot)}")
    bad = non_finite_tensors(state)
    if bad:
        raise CheckpointError(f"{where}: non-finite values (NaN or infinity) in {', '.join(bad[:3])}; retrain with "
                              f"{_train_hint(robot)}")
    _check_shapes(state, slots, n, cfg, where)  # before the model is made: its size is the file's
    model = PostureProposal(slots, n, cfg)
    try:
        model.load_state_dict(state)
    except (RuntimeError, TypeError, KeyError) as exc:
        raise CheckpointError(f"{where}: tensors do not fit the recorded sizes ({type(exc).__name__})") from None
    if not bool((model.config_std > 0).all()) or not bool((model.target_std > 0).all()):
        raise CheckpointError(f"{where}: scales must be positive; the file is corrupted")
    return model.eval()


def _declared_sizes(sizes: dict, where: str) -> tuple[int, int, ProposalCfg]:
    """The sizes the file declares (target slots, search variables, heads, hidden layers), each
    within its range (heads and hidden: the ``posture`` settings' own); one line naming the file."""
    try:
        cfg = build(ProposalCfg, {"heads": sizes["heads"], "hidden": sizes["hidden"]}, "posture")
        slots, n = (check_value(int, {"lo": 1, "hi": MAX_SIZE}, sizes[key], key) for key in ("slots", "n"))
    except ConfigError as exc:
        raise CheckpointError(f"{where}: a corrupted posture proposal checkpoint ({exc})") from None
    return slots, n, cfg


def _check_shapes(state: dict, slots: int, n: int, cfg: ProposalCfg, where: str) -> None:
    """Every tensor of ``state`` has the shape the declared sizes give (a model made on the meta
    device: nothing allocated), so a file cannot make the loader allocate more than it holds."""
    layers = sum(isinstance(k, str) and k.startswith("trunk.") for k in state) // 2
    if layers != len(cfg.hidden):  # checked first: the meta model costs time per layer
        raise CheckpointError(f"{where}: tensors do not fit the recorded sizes ({len(cfg.hidden)} hidden layers "
                              f"recorded, {layers} in the file)")
    with torch.device("meta"):
        expected = {k: tuple(v.shape) for k, v in PostureProposal(slots, n, cfg).state_dict().items()}
    got = {k: tuple(v.shape) if isinstance(v, torch.Tensor) else None for k, v in state.items()}
    if got != expected:
        wrong = sorted(str(k) for k in set(got) ^ set(expected)) or sorted(k for k in got if got[k] != expected[k])
        raise CheckpointError(f"{where}: tensors do not fit the recorded sizes ({clip(', '.join(wrong[:3]), 120)})")


_CACHE: dict[tuple, PostureProposal | None] = {}


def proposal_of(robot: Robot) -> PostureProposal | None:
    """The robot's proposal model, loaded once per file version; None when it has none (no file).
    A file that exists but cannot be used raises :class:`~graspnet_torch.errors.CheckpointError`."""
    path = posture_checkpoint(robot)
    try:
        st = path.stat()
        stamp = (st.st_size, st.st_mtime_ns)
    except OSError:
        return None
    key = (robot.name, id(robot.cfg), str(path), stamp)
    if key not in _CACHE:
        _CACHE[key] = load_proposal(robot, path)
    return _CACHE[key]
