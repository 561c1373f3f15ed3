"""Speed of the arm's loop with collision checking (env1, R3: the torch proxy every iteration)
beside the same loop without it (R1): iterations per second of one trial and trial-iterations per
second at T = 1000, fixed budgets, no early stop.

    python benchmarks/bench_arm.py [--threads 1] [--check]

Targets (issue 9): >= 1,000 iterations/s for one trial and >= 30,000 trial-iterations/s at
T = 1000 with collisions; ``--check`` exits 1 when one is missed.
"""

from __future__ import annotations

import argparse
import sys

import torch

import graspnet_torch as gt
from graspnet_torch.solver import SolverCfg
from graspnet_torch.table import format_table


def rate(kind: str, trials: int, iterations: int, repeats: int) -> float:
    """Best of ``repeats`` runs: trial-iterations per second of the loop (set-up excluded)."""
    best = 0.0
    for seed in range(repeats):
        res = gt.solve("env1", trials=trials, seed=seed, reward=gt.RewardCfg(kind=kind, a=1.5, p=2000),
                       solver=SolverCfg(threshold=None, max_iterations=iterations, history=False, final_refine=0))
        best = max(best, trials * iterations / res.outcome.wall_time_s)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rate("r3", 1, 50, 1)  # warm-up
    rows = []
    for T, iterations, repeats in ((1, 2000, 3), (1000, 60, 2)):
        with_c = rate("r3", T, iterations, repeats)
        without = rate("r1", T, iterations, repeats)
        rows.append([T, with_c, without, with_c / without])
    print(f"arm_hand on env1 (1 obstacle + the glass), torch threads: {torch.get_num_threads()}")
    print(format_table(["trials T", "trial-it/s with collisions (R3)", "without (R1)", "ratio"], rows,
                       floatfmt=".4g"))
    one, many = rows[0][1], rows[1][1]
    ok = one >= 1000 and many >= 30000
    print(f"\none trial: {one:.0f} iterations/s with collisions (target >= 1,000); T = 1000: {many:.0f} "
          f"trial-iterations/s (target >= 30,000): {'met' if ok else 'MISSED'}")
    return 1 if args.check and not ok else 0


if __name__ == "__main__":
    sys.exit(main())
