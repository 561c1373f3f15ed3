"""The surface contact model's cost: median wall time of a ``gt.solve`` call per problem in the
surface model (pads on the surface, nothing inside, fingers apart) beside the paper's point model
(its peer: the fingertip centres on the contacts), on the same problems, same seeds, same run.

    python benchmarks/contact_models.py [--poses 10] [--threads 1] [--check]

Problems: glass3, glass4, videotape5 and block5 with their objects at ``--poses`` random poses each
(the experiment ``contact``'s moved tasks), 20 trials, problem k with seed k; the two models
alternate problem by problem, after one warm-up call each. Target (``--check``): the surface
model's median at most 2x the point model's.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import bench_args, check_targets
from graspnet_torch.experiments.contact import ContactCfg, moved_tasks

SLOWER = 2.0
MODELS = ("point", "surface")


def main() -> int:
    args = bench_args(__doc__, [("--poses", int, 10)])
    print(f"torch threads: {torch.get_num_threads()}")
    problems = moved_tasks(ContactCfg(poses=args.poses))
    for model in MODELS:  # warm-up: caches, kernels, the FCNN
        gt.solve(problems[0], trials=20, seed=0, solver={"contact_model": model})
    wall = {m: [] for m in MODELS}
    ok = {m: 0 for m in MODELS}
    for k, problem in enumerate(problems):
        for model in MODELS if k % 2 == 0 else MODELS[::-1]:
            t0 = time.perf_counter()
            result = gt.solve(problem, trials=20, seed=k, solver={"contact_model": model})
            wall[model].append(time.perf_counter() - t0)
            ok[model] += int(result.success)
    median = {m: float(np.median(wall[m])) for m in MODELS}
    ratio = median["surface"] / median["point"]
    print(f"\n{len(problems)} problems (4 tasks x {args.poses} object poses), 20 trials each\n")
    print("| contact model | succeeded | median wall s | 90th percentile s | ratio to point |")
    print("|---|---|---|---|---|")
    for m in MODELS:
        print(f"| {m} | {ok[m]}/{len(problems)} | {median[m]:.3f} | {np.percentile(wall[m], 90):.3f} | "
              f"{median[m] / median['point']:.2f} |")
    return check_targets([(f"surface model median {ratio:.2f}x the point model's <= {SLOWER:g}x", ratio <= SLOWER)],
                         args.check)


if __name__ == "__main__":
    sys.exit(main())
