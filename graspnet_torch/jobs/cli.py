"""Shared behaviour of the command-line entry points: user errors are one line and exit 2."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import TypeVar

from graspnet_torch.errors import GraspnetError

__all__ = ["check_group_overrides", "user_errors_exit_2"]

T = TypeVar("T")


def user_errors_exit_2(fn: Callable[..., T]) -> Callable[..., T]:
    """Run ``fn``; a :class:`GraspnetError` prints ``error: <message>`` on stderr and exits 2."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except GraspnetError as exc:
            print(f"error: {exc}", file=sys.stderr)
            sys.exit(2)

    return wrapper


def check_group_overrides(argv: list[str], groups: tuple[str, ...]) -> None:
    """Refuse ``group=option`` arguments naming no file under ``configs/<group>/``: one line on
    stderr and exit 2, before Hydra composes anything (Hydra itself would exit 1)."""
    from graspnet_torch.paths import configs_dir

    for arg in argv:
        key, sep, value = arg.lstrip("+~").partition("=")
        if not sep or key not in groups or value in ("null", ""):
            continue
        options = sorted(p.stem for p in (configs_dir() / key).glob("*.yaml"))
        if value not in options:
            print(f"error: unknown {key} '{value}': expected one of {', '.join(options)} (configs/{key}/)",
                  file=sys.stderr)
            sys.exit(2)
