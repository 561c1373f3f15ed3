"""Random reachable problems: does the HCNN solve them?

Each problem (``gt.random_reachable_problem``): a palm pose uniform within the hand's bounds (paper
Table 1), finger joints uniform within limits, 2 to 5 fingers chosen at random; their fingertips are
the contacts, so a solution exists; the palm is searched in the same box (``palm_bounds: robot``),
as in the paper. Solved with the paper's protocol (``solver=paper``: 20 trials, 2000 iterations, each stops at
r > 0.99, fingers refined); a problem counts as solved when the result's total error is under
10 mm. ``benchmarks/solvers.py`` compares every solver, the default included, on such problems.

    python benchmarks/hcnn_random_problems.py [--problems 100]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.io import atomic_write_text
from graspnet_torch.solver import SolverCfg


def random_problem(robot, seed: int) -> gt.GraspProblem:
    """``gt.random_reachable_problem`` searched in the paper's box (``palm_bounds: robot``, Table 1)."""
    problem = gt.random_reachable_problem(robot, seed)
    return gt.GraspProblem.from_mapping({**problem.to_mapping(), "palm_bounds": "robot"}, robot_cfg=robot.cfg,
                                        source=problem.source)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=100)
    ap.add_argument("--out", default="reports/random_problems.md")
    ap.add_argument("--check", action="store_true", help="exit 1 when fewer than 95 % are solved to < 10 mm")
    args = ap.parse_args()
    torch.set_num_threads(1)
    robot = gt.load_robot("hand")
    errors, fingers, seconds = [], [], []
    for seed in range(args.problems):
        problem = random_problem(robot, seed)
        t0 = time.perf_counter()
        result = gt.solve(problem, trials=20, seed=0, solver=SolverCfg.paper())
        seconds.append(time.perf_counter() - t0)
        errors.append(result.total_error_mm)
        fingers.append(len(problem.fingers))
        if seed % 10 == 9:
            e = np.array(errors)
            print(f"{seed + 1} problems: {np.mean(e < 10) * 100:.1f} % solved to < 10 mm", flush=True)
    e, nf = np.array(errors), np.array(fingers)
    lines = ["# HCNN on random reachable problems", "",
             f"`python benchmarks/hcnn_random_problems.py`: {args.problems} problems (palm pose uniform within Table 1 "
             "bounds, joints uniform within limits, 2-5 random fingers, their fingertips as contacts), the "
             "paper's protocol (`solver=paper`: 20 trials, 2000 iterations, stop at r > 0.99).", "",
             f"**Solved to total error < 10 mm: {np.mean(e < 10) * 100:.1f} %** (target: at least 95 %); "
             f"< 1 mm: {np.mean(e < 1) * 100:.1f} %; median {np.median(e):.3f} mm; mean solve time "
             f"{np.mean(seconds):.2f} s.", "", "| fingers | problems | solved < 10 mm | median error mm |",
             "|---|---|---|---|"]
    for k in sorted(set(nf.tolist())):
        sel = nf == k
        lines.append(f"| {k} | {int(sel.sum())} | {np.mean(e[sel] < 10) * 100:.1f} % | {np.median(e[sel]):.3f} |")
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print(f"solved {np.mean(e < 10) * 100:.1f} % (< 10 mm); wrote {args.out}")
    solved = float(np.mean(e < 10) * 100)
    return check_targets([(f"solver=paper: {solved:.1f} % solved to < 10 mm >= 95 %", solved >= 95)], args.check)


if __name__ == "__main__":
    sys.exit(main())
