"""Ctrl-C in a command: one line and exit 130, whatever a library made of the interrupt; in a
training job, the loop stops between two steps, keeps its state and says so.

A command runs inside :func:`remembering_interrupts`: Ctrl-C is Python's usual
``KeyboardInterrupt``, remembered (:func:`interrupted`), because a library may turn it into another
exception (omegaconf's flag restore in Hydra's composition) or swallow it (optional imports that
catch ImportError or BaseException: pytorch_kinematics', trimesh's); the command line still stops
with :func:`exit_interrupted`'s line, and a job's loop calls :func:`stop_if_interrupted` between
its items.

A training loop runs inside :func:`stop_on_interrupt`: the first SIGINT (Ctrl-C) only sets
:attr:`StopRequest.requested`; the loop checks it after each step (or epoch), writes its
resumable state and raises :class:`~graspnet_torch.errors.Interrupted` with one line saying
where the state is and how to resume (the command line prints it and exits 130). A second
Ctrl-C interrupts at once (``KeyboardInterrupt``: the state last written is kept, writes are
atomic). Outside the loop (drawing data, the closing evaluation) Ctrl-C is the usual
``KeyboardInterrupt``, which the jobs turn into the same one line.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

from graspnet_torch.errors import say

__all__ = ["StopRequest", "exit_interrupted", "interrupted", "remembering_interrupts", "resume_hint",
           "stop_if_interrupted", "stop_on_interrupt"]

_interrupted = False  # a Ctrl-C reached the command (inside remembering_interrupts)


def _on_sigint(signum: int, frame: object) -> None:
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def remembering_interrupts() -> Iterator[None]:
    """While inside, Ctrl-C raises ``KeyboardInterrupt`` as usual and is remembered (forgotten on
    entering and leaving); the previous handler is put back on leaving. Off the main thread: nothing
    changes."""
    global _interrupted
    _interrupted = False
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        _interrupted = False


def interrupted() -> bool:
    """Whether a Ctrl-C reached this command (:func:`remembering_interrupts`), whatever became of it."""
    return _interrupted


def stop_if_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` where a Ctrl-C reached this command and a library swallowed it."""
    if _interrupted:
        raise KeyboardInterrupt


def exit_interrupted(started: bool) -> None:
    """Ctrl-C's one line on stderr and exit 130: ``started``, a job may have written files (whole:
    writes are atomic), else nothing was written."""
    if started:
        say("interrupted (Ctrl-C): files written before it are whole, the one being written is not there")
    else:
        say("interrupted (Ctrl-C) before the job started: nothing written")
    sys.exit(130)


class StopRequest:
    """Whether Ctrl-C asked the loop to stop (``requested``)."""

    def __init__(self) -> None:
        self.requested = False


@contextlib.contextmanager
def stop_on_interrupt() -> Iterator[StopRequest]:
    """While inside, the first SIGINT sets ``requested`` and a second raises ``KeyboardInterrupt``;
    the previous handler is put back on leaving. Off the main thread (where Python allows no signal
    handler) nothing changes and ``requested`` stays false."""
    stop = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum, frame):
        if stop.requested:
            raise KeyboardInterrupt
        stop.requested = True

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)


def resume_hint(state_path: Path, kept: str | None) -> str:
    """The line of an interrupted training: the state it kept (``kept``: which step or epoch;
    None: none written yet) and how to resume."""
    if kept is None:
        return f"before this run wrote a training state ({state_path})"
    return f"state {kept} kept in {state_path}; resume with the same command and resume=true"
