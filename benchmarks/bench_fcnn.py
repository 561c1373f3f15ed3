"""FCNN finger IK vs pytorch-kinematics PseudoInverseIK on the same reachable targets.

For every finger of the hand: ``--sets`` sets of 10,000 targets from joint angles uniform within
limits (seeds used by neither training nor tests). Methods: the FCNN's competition alone, + 1/2/3
refinement iterations (eq. 5), + 2/3 iterations refining the 2 best experts' answers, the latter
with the random-restart fallback for the rare unsolved target; and PseudoInverseIK (position only,
10 random restarts drawn fresh per call, early stop on convergence within 1 mm, at most 50
iterations). PseudoInverseIK shares its 10 restarts among all targets of a call, so its success
varies from draw to draw: hence several sets, each with fresh restarts, summed. Every method's
answer is scored the same way: float64 forward kinematics of the returned joints against the
target. One run, side by side; prints success within 1 mm, median / p99 error, joint-limit
compliance, targets per second and the speed ratio to the peer.

    python benchmarks/bench_fcnn.py [--targets 10000] [--sets 3] [--threads 1]
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets, time_interleaved
from graspnet_torch.fcnn import load_finger_ik
from graspnet_torch.fcnn.evaluate import error_stats, heldout_targets
from graspnet_torch.robot import ChainKernel
from graspnet_torch.table import format_table

BENCH_SEED = 31_337
VARIANTS = [  # name, refinement iterations, candidates, fallback restarts
    ("FCNN competition", 0, 1, 0), ("FCNN +1 refine", 1, 1, 0), ("FCNN +2 refine", 2, 1, 0),
    ("FCNN +3 refine", 3, 1, 0), ("FCNN +2 refine, 2 cand.", 2, 2, 0), ("FCNN +3 refine, 2 cand.", 3, 2, 0),
    ("FCNN +2 refine, 2 cand., fallback", 2, 2, 10)]


def pk_solver(robot, finger: str, generator: torch.Generator):
    import pytorch_kinematics as pk

    spec = robot.fingers[finger].chain.spec
    chain = robot.urdf.serial_chain(spec.root, spec.tip).to(dtype=torch.float32)
    lo = torch.tensor(spec.lower, dtype=torch.float32)
    hi = torch.tensor(spec.upper, dtype=torch.float32)

    def solve(x: torch.Tensor) -> torch.Tensor:
        retry = lo + (hi - lo) * torch.rand(10, spec.n_joints, generator=generator)  # fresh restarts per call
        ik = pk.PseudoInverseIK(chain, pos_tolerance=1e-3, rot_tolerance=math.inf, orientation_weight=0.0,
                                retry_configs=retry, max_iterations=50, early_stopping_any_converged=True,
                                early_stopping_no_improvement="all")
        sol = ik.solve(pk.Transform3d(pos=x))
        best = sol.err_pos.argmin(dim=1)
        return sol.solutions[torch.arange(x.shape[0]), best]

    return solve


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=10_000)
    ap.add_argument("--sets", type=int, default=3, help="target sets per finger, each with fresh restarts")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--fingers", nargs="*", default=None)
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    robot = gt.load_robot("hand")
    ik = load_finger_ik(robot)
    rows, summary = [], []
    n_total = args.targets * args.sets
    for finger in args.fingers or robot.finger_names:
        spec = robot.fingers[finger].chain.spec
        ref = ChainKernel(spec)
        lo, hi = torch.tensor(spec.lower), torch.tensor(spec.upper)
        errors = {name: [] for name, *_ in VARIANTS}
        errors["pk"] = []
        seconds = dict.fromkeys(errors, 0.0)
        in_limits = dict.fromkeys(errors, True)
        for k in range(args.sets):
            seed = BENCH_SEED + k
            _, x = heldout_targets(ik, finger, args.targets, seed=seed)
            fns = [lambda r=r, c=c, fb=fb, x=x, finger=finger: ik.solve(finger, x, refine=r, candidates=c,
                                                                         fallback_restarts=fb)[0]
                   for _, r, c, fb in VARIANTS]
            times = time_interleaved(fns, min_time=0.6)
            peer = pk_solver(robot, finger, torch.Generator().manual_seed(seed))
            peer(x[:100])  # warm-up
            t0 = time.perf_counter()
            q_pk = peer(x)
            seconds["pk"] += time.perf_counter() - t0
            outputs = [(name, fn(), t) for (name, *_), fn, t in zip(VARIANTS, fns, times, strict=True)]
            for name, q, t in [*outputs, ("pk", q_pk, 0.0)]:
                q = q.double()
                errors[name].append((ref.position(q) - x.double()).norm(dim=-1))
                in_limits[name] &= bool(((q >= lo - 1e-5) & (q <= hi + 1e-5)).all())
                seconds[name] += t
        st_pk = error_stats(torch.cat(errors["pk"]))
        for name, *_ in VARIANTS:
            st = error_stats(torch.cat(errors[name]))
            rows.append([finger, name, round(st["within_1mm_pct"], 3), st["median_mm"], st["p99_mm"], in_limits[name],
                         n_total / seconds[name], seconds["pk"] / seconds[name]])
            if name in ("FCNN +3 refine", "FCNN +2 refine, 2 cand.", "FCNN +2 refine, 2 cand., fallback"):
                summary.append((finger, name, st["within_1mm_pct"], st_pk["within_1mm_pct"],
                                seconds["pk"] / seconds[name]))
        rows.append([finger, "PseudoInverseIK (10 restarts)", round(st_pk["within_1mm_pct"], 3), st_pk["median_mm"],
                     st_pk["p99_mm"], in_limits["pk"], n_total / seconds["pk"], 1.0])
        print(f"  {finger}: PseudoInverseIK {seconds['pk']:.1f} s for {n_total} targets, "
              f"success {st_pk['within_1mm_pct']:.3f}%", flush=True)
    print(f"\n{args.sets} x {args.targets} reachable targets per finger, float32, {args.threads} threads; "
          "speedup = PseudoInverseIK time / method time")
    print(format_table(["finger", "method", "<1 mm %", "median mm", "p99 mm", "in limits", "targets/s",
                        "speedup"], rows, floatfmt=".4g"))
    print("\nFCNN + refinement vs PseudoInverseIK (success within 1 mm over all sets, speedup):")
    for finger, name, ours, theirs, speed in summary:
        verdict = "equal or better" if ours >= theirs else "LOWER"
        print(f"  {finger:7s} {name:34s} {ours:7.3f}% vs {theirs:7.3f}%  ({verdict}),  {speed:6.0f}x faster")
    checks = [(f"{finger}, {name}: {ours:.3f} % within 1 mm >= 99.5 % and >= PseudoInverseIK ({theirs:.3f} %), "
               f"{speed:.0f}x faster >= 10x", ours >= 99.5 and ours >= theirs and speed >= 10)
              for finger, name, ours, theirs, speed in summary if name == "FCNN +3 refine"]
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
