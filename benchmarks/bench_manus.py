"""Speed of the MANUS loop (task ``cube``) with its defaults: two refine steps per proposal and
the collision proxy every iteration (table, cube, floor, the arm against its own links, R3),
beside the bare loop (R1, no refine, no collisions) in the same run: iterations per second of
one trial and trial-iterations per second at T = 1000, fixed budgets, no early stop.

    python benchmarks/bench_manus.py [--threads 1] [--check]

Targets (issue 10): >= 2,000 iterations/s for one trial and >= 100,000 trial-iterations/s at
T = 1000 with the defaults; ``--check`` exits 1 when one is missed.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import bench_args, loop_rate, rate_rows
from graspnet_torch.table import format_table


def main() -> int:
    args = bench_args(__doc__)

    def rate(bare: bool) -> Callable[[int, int, int], float]:
        reward = gt.RewardCfg(kind="r1" if bare else "r3", a=1.0, p=50)
        return lambda T, iterations, repeats: loop_rate("cube", T, iterations, repeats, reward, 0 if bare else 2)

    rate(False)(1, 50, 1)  # warm-up
    rows = rate_rows(rate(False), rate(True), ((1, 1000, 3), (1000, 30, 2)))
    print(f"manus on cube (table, cube, floor, self-collision), torch threads: {torch.get_num_threads()}")
    print(format_table(["trials T", "trial-it/s defaults (refine 2, collisions, R3)", "bare loop (R1)", "ratio"],
                       rows, floatfmt=".4g"))
    one, many = rows[0][1], rows[1][1]
    ok = one >= 2000 and many >= 100_000
    print(f"\none trial: {one:.0f} iterations/s (target >= 2,000); T = 1000: {many:.0f} trial-iterations/s "
          f"(target >= 100,000): {'met' if ok else 'MISSED'}")
    return 1 if args.check and not ok else 0


if __name__ == "__main__":
    sys.exit(main())
