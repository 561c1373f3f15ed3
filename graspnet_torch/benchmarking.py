"""Timing helpers for benchmarks/ (not used by the library itself)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

__all__ = ["time_interleaved"]


def time_interleaved(fns: Sequence[Callable[[], object]], min_time: float = 0.3, rounds: int = 5) -> list[float]:
    """Seconds per call of each function, measured side by side.

    Each round times every function in turn (so slow drifts of a shared machine hit all of them
    alike) over at least ``min_time / rounds`` seconds; the result is each function's fastest
    round, the usual estimator of the undisturbed cost.
    """
    for fn in fns:  # warm-up: allocations, program compilation, caches
        fn()
    best = [float("inf")] * len(fns)
    for _ in range(rounds):
        for k, fn in enumerate(fns):
            n, start = 0, time.perf_counter()
            while True:
                fn()
                n += 1
                elapsed = time.perf_counter() - start
                if elapsed >= min_time / rounds:
                    break
            best[k] = min(best[k], elapsed / n)
    return best
