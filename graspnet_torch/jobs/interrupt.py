"""Ctrl-C in a training job: the loop stops between two steps, keeps its state and says so.

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
import threading
from collections.abc import Iterator
from pathlib import Path

__all__ = ["StopRequest", "resume_hint", "stop_on_interrupt"]


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
