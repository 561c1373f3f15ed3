"""User-facing errors. Each carries one line that says what is wrong and where; :func:`say`
writes such a line on stderr."""

from __future__ import annotations

import sys

__all__ = ["CheckpointError", "ConfigError", "GraspnetError", "InternalError", "Interrupted", "ProblemError",
           "say"]


class GraspnetError(Exception):
    """Base class of the errors a user can cause (bad config, bad problem file, bad checkpoint).

    Command-line entry points turn these into one line on stderr and exit status 2; anything
    else is a bug and keeps its traceback.
    """


class ConfigError(GraspnetError, ValueError):
    """A robot or run configuration is invalid (unknown name, missing file, bad key or value)."""


class ProblemError(GraspnetError, ValueError):
    """A grasp problem (file or object) is invalid."""


class CheckpointError(GraspnetError, ValueError):
    """A checkpoint file is missing, corrupted or does not match the robot it is loaded for."""


class InternalError(RuntimeError):
    """A failure that is not the user's input but is still reported in one line: a result that is
    not finite (NaN or infinity) is never written. Command-line entry points exit 1 on it."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) ended a job, which says in one line what it kept (a training: its state,
    and how to resume). A ``KeyboardInterrupt``, so a program's own handling still catches it;
    command-line entry points exit 130 on it (128 + SIGINT, the shells' convention)."""


def say(line: str) -> None:
    """Write ``line`` and its newline on stderr in one write and flush it.

    ``print(line, file=sys.stderr)`` writes the text and the newline apart: the jobs of a parallel
    sweep share one stderr, and their lines came out run together ("...whole...whole" then two
    empty lines). One write of under 4096 bytes to a pipe or terminal is never split (POSIX
    ``PIPE_BUF``), so each job's line stays whole.
    """
    sys.stderr.flush()
    sys.stderr.write(line + "\n")
    sys.stderr.flush()
