"""How many CPU threads torch uses for the package's work, and the caller's count put back after.

On a machine whose cores are busy, two torch threads run a solve or FCNN training many times
slower than one (``benchmarks/bench_threads.py`` measures both side by side; docs "Which solver?",
"Threads"), so the Python API (:func:`gt.solve`, :func:`gt.solve_many`, :class:`gt.Solver`) runs its work on **one
thread by default**, as the command-line jobs do, and restores the caller's count afterwards.

- ``threads=N`` on a call: N threads for that call.
- :func:`set_default_threads`: the default of every later call (a job sets its ``threads`` here;
  a benchmark its ``--threads``); ``None``: leave torch's own setting alone.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch

from graspnet_torch.errors import ConfigError

__all__ = ["check_threads", "default_threads", "set_default_threads", "torch_threads"]

MAX_THREADS = 1024
_default: int | None = 1


def check_threads(n: object, where: str = "threads") -> int | None:
    """``n`` if it is a thread count (an integer in [1, 1024]) or None, else a :class:`ConfigError`."""
    if n is None:
        return None
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_THREADS:
        raise ConfigError(f"{where}={n!r}: expected an integer in [1, {MAX_THREADS}] or None")
    return n


def default_threads() -> int | None:
    """The thread count of a call that gives none (1 unless :func:`set_default_threads` changed it;
    None: torch's own setting)."""
    return _default


def set_default_threads(n: int | None) -> None:
    """The thread count of every later call that gives none; None: torch's own setting."""
    global _default
    _default = check_threads(n, "threads")


@contextlib.contextmanager
def torch_threads(n: int | None = None) -> Iterator[int]:
    """Inside, torch uses ``n`` CPU threads (None: :func:`default_threads`); the caller's count is
    put back on leaving, also after an error. Yields the count in force."""
    n = check_threads(n, "threads")
    want = n if n is not None else _default
    before = torch.get_num_threads()
    if want is not None and want != before:
        torch.set_num_threads(want)
    try:
        yield torch.get_num_threads()
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)
