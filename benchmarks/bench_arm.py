"""Speed of the arm's loop with collision checking (env1, R3: the torch proxy every iteration)
beside the same loop without it (R1): iterations per second of one trial and trial-iterations per
second at T = 1000, fixed budgets, no early stop.

    python benchmarks/bench_arm.py [--threads 1] [--check]

Targets (issue 9): >= 1,000 iterations/s for one trial and >= 30,000 trial-iterations/s at
T = 1000 with collisions; ``--check`` exits 1 when one is missed.
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

    def rate(kind: str) -> Callable[[int, int, int], float]:
        return lambda T, iterations, repeats: loop_rate("env1", T, iterations, repeats,
                                                        gt.RewardCfg(kind=kind, a=1.5, p=2000))

    rate("r3")(1, 50, 1)  # warm-up
    rows = rate_rows(rate("r3"), rate("r1"), ((1, 2000, 3), (1000, 60, 2)))
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
