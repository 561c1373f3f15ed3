"""Many calls from a program: per-call overhead of ``gt.Solver.solve`` beside ``gt.solve``, and the
single-problem wall time on random reachable 4-5 finger hand problems.

    python benchmarks/calls.py [--problems 100] [--threads 1] [--check]

Overhead = a call's wall time minus its search (the result's ``wall_time_s``: the loop and the
finish), median over calls after the first: the shipped hand on random reachable problems, the
shipped hand on ``glass3`` (an object: its collision models cached by geometry), and a hand by
config (examples/trifinger). Targets: overhead <= 2 ms; the median single-problem wall time
<= 15 ms with >= 99.5 % of the problems below 1 mm (total error).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.paths import repo_root
from graspnet_torch.robot import load_robot_cfg

OVERHEAD_MS, MEDIAN_MS, BELOW_PCT = 2.0, 15.0, 99.5


def _calls(call, problems) -> tuple[list[float], list[float], list[gt.GraspResult]]:
    walls, searches, results = [], [], []
    call(problems[0])  # the first call builds and caches
    for p in problems:
        t0 = time.perf_counter()
        r = call(p)
        walls.append(time.perf_counter() - t0)
        searches.append(r.best.wall_time_s)
        results.append(r)
    return walls, searches, results


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=100)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch threads: {torch.get_num_threads()}")
    hand = gt.load_robot("hand")
    problems = [gt.random_reachable_problem(hand, 40_000 + k, (4, 5)) for k in range(args.problems)]
    trifinger = load_robot_cfg(str(repo_root() / "examples" / "trifinger" / "trifinger.yaml"))
    tri = gt.Robot(trifinger)
    tri_problems = [gt.random_reachable_problem(tri, 41_000 + k) for k in range(min(args.problems, 40))]
    cases = [("hand, random 4-5 fingers", gt.Solver("hand"), lambda p: gt.solve(p), problems),
             ("hand, glass3 (object)", gt.Solver("hand"), lambda p: gt.solve(p), ["glass3"] * 10),
             ("trifinger by config", gt.Solver(trifinger), lambda p: gt.solve(p), tri_problems)]
    rows, checks = [], []
    for name, solver, wrapper, batch in cases:
        for how, call in (("gt.Solver.solve", solver.solve), ("gt.solve", wrapper)):
            walls, searches, results = _calls(call, batch)
            over = statistics.median(w - s for w, s in zip(walls, searches, strict=True)) * 1e3
            wall = statistics.median(walls) * 1e3
            below = sum(r.best.total_error_mm < 1 for r in results) / len(results) * 100
            rows.append(f"| {name} | {how} | {over:.2f} | {wall:.1f} | {below:.1f} |")
            if how == "gt.Solver.solve":
                checks.append((f"{name}: per-call overhead {over:.2f} ms <= {OVERHEAD_MS:g} ms", over <= OVERHEAD_MS))
                if name.startswith("hand, random"):
                    checks.append((f"{name}: median wall {wall:.1f} ms <= {MEDIAN_MS:g} ms", wall <= MEDIAN_MS))
                    checks.append((f"{name}: {below:.1f} % below 1 mm >= {BELOW_PCT:g} %", below >= BELOW_PCT))
    print("| case | call | overhead ms (median) | wall ms (median) | < 1 mm % |")
    print("|---|---|---|---|---|")
    print("\n".join(rows))
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
