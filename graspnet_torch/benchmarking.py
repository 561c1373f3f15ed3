"""Timing helpers for benchmarks/ (not used by the library itself)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import graspnet_torch as gt
from graspnet_torch.solver import SolverCfg
from graspnet_torch.threads import set_default_threads

if TYPE_CHECKING:
    from graspnet_torch.solver.config import RewardCfg
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["bench_args", "check_targets", "loop_rate", "rate_rows", "time_interleaved"]


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


def check_targets(checks: Sequence[tuple[str, bool]], check: bool) -> int:
    """Print one line per target (``met`` or ``MISSED``); the exit status of a benchmark: 1 when
    ``check`` and a target is missed, else 0."""
    for text, ok in checks:
        print(f"{'met   ' if ok else 'MISSED'}  {text}")
    return 1 if check and not all(ok for _, ok in checks) else 0


def bench_args(doc: str, extra: Sequence[tuple[str, type, Any]] = ()) -> argparse.Namespace:
    """``--threads`` (default 1, pinned here: on busy cores two threads run many times slower than
    one, ``benchmarks/bench_threads.py``) and ``--check`` (exit 1 when a target is missed), the options every speed
    benchmark takes; ``extra``: its own options as (flag, type, default)."""
    import torch

    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    for flag, kind, default in extra:
        ap.add_argument(flag, type=kind, default=default)
    args = ap.parse_args()

    torch.set_num_threads(args.threads)
    set_default_threads(args.threads)  # the Python API's calls use it too (their own default is 1)
    return args


def loop_rate(task: str | GraspProblem, trials: int, iterations: int, repeats: int, reward: RewardCfg,
              refine: int | None = None) -> float:
    """Best of ``repeats`` solves of a task (a name or a problem): trial-iterations per second of
    the loop (set-up excluded), a fixed budget with no early stop and no polish; ``refine``: the
    steps inside the loop per evaluation (FCNN refinement; a gripper's settling steps), None: the
    defaults. The paper's point contact model: the loop these rates were set for (in the surface
    model, the default with an object, a fixed-budget run also pays its finish: the whole polish
    with every link's depth on every trial, several times the loop's cost;
    ``benchmarks/mesh_objects.py`` measures it)."""
    best = 0.0
    for seed in range(repeats):
        fingers, gripper = {"final_refine": 0}, {"polish_iterations": 0}  # no polish after the loop
        if refine is not None:
            fingers, gripper = {**fingers, "refine": refine}, {**gripper, "settle": refine}
        solver = SolverCfg.from_mapping({"threshold": None, "max_iterations": iterations, "history": False,
                                         "fingers": fingers, "gripper": gripper, "contact_model": "point"})
        res = gt.solve(task, trials=trials, seed=seed, solver=solver, reward=reward)
        best = max(best, trials * iterations / res.outcome.wall_time_s)
    return best


def rate_rows(full: Callable[[int, int, int], float], peer: Callable[[int, int, int], float],
              sizes: Sequence[tuple[int, int, int]]) -> list[list[float]]:
    """[T, full, peer, full / peer] for each (trials T, iterations, repeats), the two measured side
    by side."""
    rows = []
    for T, iterations, repeats in sizes:
        a, b = full(T, iterations, repeats), peer(T, iterations, repeats)
        rows.append([T, a, b, a / b])
    return rows
