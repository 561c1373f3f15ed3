"""Shared behaviour of the command-line entry points: user errors are one line and exit 2."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import TypeVar

from graspnet_torch.errors import GraspnetError

__all__ = ["user_errors_exit_2"]

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
