"""Locations of the project's data: configs, URDFs and checkpoints.

Paths resolve from the package (the repository root is the parent of ``graspnet_torch/``), never
from the working directory. ``GRASPNET_TORCH_ROOT`` overrides the root, e.g. for an installed copy
that keeps its data elsewhere.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["checkpoints_dir", "configs_dir", "repo_root", "resolve_repo_path", "urdf_dir"]

_PACKAGE_ROOT = Path(__file__).resolve().parent.parent  # resolved once: a solve asks for it on every call


def repo_root() -> Path:
    """The repository root: the folder that holds ``configs/``, ``urdf/`` and ``checkpoints/``."""
    env = os.environ.get("GRASPNET_TORCH_ROOT")
    return Path(env).resolve() if env else _PACKAGE_ROOT


def configs_dir() -> Path:
    return repo_root() / "configs"


def urdf_dir() -> Path:
    return repo_root() / "urdf"


def checkpoints_dir() -> Path:
    return repo_root() / "checkpoints"


def resolve_repo_path(path: str | os.PathLike) -> Path:
    """An absolute path as is; a relative one against the repository root."""
    p = Path(path).expanduser()
    return p if p.is_absolute() else repo_root() / p
