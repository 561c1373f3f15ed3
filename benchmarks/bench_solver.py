"""Speed of the closed loop: iterations per second of one trial, and trial-iterations per second
with T = 1, 30, 1000 trials batched, with the ratio to the single-trial loop (glass3, default
settings, fixed budgets, no early stop).

    python benchmarks/bench_solver.py [--threads 1] [--check]

Targets (``--check`` exits 1 when one is missed): one trial >= 2,000 iterations/s; T = 1000
>= 50,000 trial-iterations/s.
"""

from __future__ import annotations

import argparse
import sys

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.solver import SolverCfg
from graspnet_torch.table import format_table


def rate(trials: int, iterations: int, repeats: int, task: str = "glass3") -> float:
    """Best of ``repeats`` runs: trial-iterations per second of the loop (setup excluded)."""
    best = 0.0
    for seed in range(repeats):
        solver = SolverCfg.paper(threshold=None, max_iterations=iterations)  # the loop itself, no polish
        res = gt.solve(task, trials=trials, seed=seed, solver=solver)
        best = max(best, trials * iterations / res.outcome.wall_time_s)
    return best


SINGLE_TARGET = 2_000
BATCH_TARGET = 50_000


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch threads: {torch.get_num_threads()}")
    rate(1, 100, 1)  # warm-up
    single = rate(1, 2000, 3)
    rows = [[1, single, single, 1.0]]
    for T, iterations in ((30, 1000), (1000, 200)):
        r = rate(T, iterations, 2)
        rows.append([T, r / T, r, r / single])
    print(f"glass3 (3 fingers), {args.threads} threads; paper: ~108 iterations/s (MATLAB, one trial)")
    print(format_table(["trials T", "iterations/s", "trial-iterations/s", "ratio to one trial"], rows, floatfmt=".4g"))
    five = rate(1, 2000, 3, task="videotape5")
    print(f"\none trial: {single:.0f} iterations/s (target >= 2,000); T = 1000: {rows[-1][2]:.0f} "
          f"trial-iterations/s (target >= 50,000); five fingers (videotape5), one trial: {five:.0f} iterations/s")
    checks = [(f"one trial: {single:.0f} iterations/s >= {SINGLE_TARGET:,}", single >= SINGLE_TARGET),
              (f"T = 1000: {rows[-1][2]:.0f} trial-iterations/s >= {BATCH_TARGET:,}", rows[-1][2] >= BATCH_TARGET)]
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
