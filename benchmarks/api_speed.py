"""The Python API from a plain program: ``gt.solve_many``'s throughput and ``gt.Solver.solve``'s
per-call overhead on random hand problems, with the API's default thread count beside torch's own.

    python benchmarks/api_speed.py [--problems 1000] [--seeds 10000,20000,30000,60000] [--calls 200] [--check]

- ``gt.solve_many``: on each seed set (``--seeds``: problem k of the set with base b is
  ``gt.random_reachable_problem(hand, b + k, (3, 5))``), P random reachable problems of the shipped
  hand with 3-5 contact fingers (mixed subsets), T = 4 trials each (as benchmarks/polish.py's), one
  call after a warm-up call: problems per second, each set's and the minimum over the sets. A set
  with a problem no trial solves runs that problem's trials to the iteration budget while the
  others have stopped; the minimum is what the target holds for. Target >= 1,000 (the minimum).
- ``gt.Solver("hand").solve``: N random reachable problems of 2-5 fingers (random subsets), one
  call each after a first call on another problem; per-call overhead = the call's wall time minus
  its search (the result's ``outcome.wall_time_s``: the proposal starts, the loop and the finish;
  what stays is the environment's set-up and the result): median and 90th percentile. Each
  setting gets a robot of its own, so the finger subsets it meets are new to it. Target: median
  <= 2 ms.

Both are measured twice in one run: with the API's default (``threads=None``: one thread,
:mod:`graspnet_torch.threads`) and, as the peer, with torch's own thread count
(``gt.set_default_threads(None)``); ratios are API default / peer. Unlike the other speed
benchmarks this one sets no thread count (no ``--threads``): it measures what a plain program
gets. The targets are checked on the API's default.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.threads import default_threads

PROBLEMS_PER_S, OVERHEAD_MS = 1000.0, 2.0
MANY_TRIALS = 4


def solve_many_rate(problems: list[gt.GraspProblem]) -> tuple[float, float, int]:
    """Problems per second of one ``gt.solve_many`` call (after a warm-up call), the share of
    problems solved (%) and the most iterations any problem ran."""
    gt.solve_many(problems[:8], trials=MANY_TRIALS, seed=0)  # warm-up: the robot, its FCNN, the proposals
    t0 = time.perf_counter()
    results = gt.solve_many(problems, trials=MANY_TRIALS, seed=0)
    wall = time.perf_counter() - t0
    solved = sum(bool(r.success) for r in results) / len(results) * 100
    return len(problems) / wall, solved, max(int(r.outcome.iterations.max()) for r in results)


def solver_overhead(problems: list[gt.GraspProblem]) -> tuple[float, float]:
    """Median and 90th percentile (ms) of ``gt.Solver.solve``'s wall time minus its search, over
    ``problems[1:]`` (the first call, on ``problems[0]``, loads the robot's models)."""
    solver = gt.Solver(gt.load_robot("hand"))  # a robot of its own: no finger subset seen before
    solver.solve(problems[0])
    over = []
    for p in problems[1:]:
        t0 = time.perf_counter()
        result = solver.solve(p)
        over.append((time.perf_counter() - t0 - result.outcome.wall_time_s) * 1e3)
    over.sort()
    return statistics.median(over), over[min(len(over) - 1, int(0.9 * len(over)))]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=1000, help="problems of each solve_many call")
    ap.add_argument("--seeds", default="10000,20000,30000,60000",
                    help="the solve_many seed sets: comma-separated bases b (problem k: seed b + k)")
    ap.add_argument("--calls", type=int, default=200, help="gt.Solver.solve calls")
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    args = ap.parse_args()
    bases = [int(b) for b in args.seeds.split(",")]
    own = torch.get_num_threads()
    print(f"torch threads: {own} (torch's own, this process); the API's default: {default_threads()}")
    hand = gt.load_robot("hand")
    sets = {b: [gt.random_reachable_problem(hand, b + k, (3, 5)) for k in range(args.problems)] for b in bases}
    calls = [gt.random_reachable_problem(hand, 40_000 + k, (2, 5)) for k in range(args.calls + 1)]
    rates: dict[str, dict[int, float]] = {}
    figures = {}
    for name, threads in (("API default", default_threads()), ("torch's own", None)):
        gt.set_default_threads(threads)
        rates[name] = {}
        for b, many in sets.items():
            rate, solved, iterations = solve_many_rate(many)
            rates[name][b] = rate
            print(f"{name} ({threads or own} thread(s)): gt.solve_many, seeds {b}+k: {rate:,.0f} problems/s "
                  f"({solved:.1f} % solved, at most {iterations} iterations)")
        median, p90 = solver_overhead(calls)
        figures[name] = (median, p90)
        print(f"{name} ({threads or own} thread(s)): gt.Solver.solve overhead median {median:.2f} ms, p90 {p90:.2f} ms")
    gt.set_default_threads(1)
    (median, p90), (peer_median, peer_p90) = figures["API default"], figures["torch's own"]
    mine, peer = rates["API default"], rates["torch's own"]
    print(f"\n| call | API default ({default_threads()} thread) | torch's own ({own}) | ratio |")
    print("|---|---|---|---|")
    what = f"gt.solve_many, {args.problems} problems x {MANY_TRIALS} trials"
    for b in bases:
        print(f"| {what}, seeds {b}+k: problems/s | {mine[b]:,.0f} | {peer[b]:,.0f} | {mine[b] / peer[b]:.2f} |")
    rate, peer_rate = min(mine.values()), min(peer.values())
    print(f"| {what}, minimum over the {len(bases)} seed sets: problems/s | {rate:,.0f} | {peer_rate:,.0f} | "
          f"{rate / peer_rate:.2f} |")
    print(f"| gt.Solver.solve overhead, median ms | {median:.2f} | {peer_median:.2f} | {median / peer_median:.2f} |")
    print(f"| gt.Solver.solve overhead, p90 ms | {p90:.2f} | {peer_p90:.2f} | {p90 / peer_p90:.2f} |")
    checks = [(f"gt.solve_many {rate:,.0f} problems/s (minimum over seed sets {args.seeds}) >= "
               f"{PROBLEMS_PER_S:,.0f}", rate >= PROBLEMS_PER_S),
              (f"gt.Solver.solve overhead median {median:.2f} ms <= {OVERHEAD_MS:g} ms", median <= OVERHEAD_MS)]
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
