"""Paper section 7.2 regenerated: the MANUS two-point grasp of a cube over a workspace (64 positions
x 30 runs), with the damped least-squares and CMA-ES baselines on the same problems, and Fig. 12
(the experiment ``manus`` of :mod:`graspnet_torch.experiments`); and this project's own checks of
issue 10: an approach near a known solution, and random reachable problems.

    python benchmarks/manus_protocol.py [--runs 30] [--threads 1] [--out reports] [--check]

Writes ``<out>/manus_protocol.md``, ``fig12_criteria.png`` and ``fig12_posture.png``; ``--check``
exits 1 when a target is missed.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.experiments import ManusCfg, run_manus
from graspnet_torch.io import atomic_write_text
from graspnet_torch.solver.api import robot_and_ik
from graspnet_torch.tasks.manus import cube_problem, protocol_positions
from graspnet_torch.tasks.problem import GraspProblem


def approach_check(results: list, trials: int, seed: int = 7) -> dict:
    """At every position with a collision-free solution from the protocol, an ``approach`` drawn
    within 0.15 m (base x, y) and 20 degrees (every revolute joint) of it; solved with the
    default search window (+-0.2 m, +-30 degrees); the result's best counts."""
    robot, _ = robot_and_ik("manus")
    rng = np.random.default_rng(seed)
    problems = []
    for (x, y), res in zip(protocol_positions(), results, strict=True):
        good = [t for t in res.trials if t.collisions == 0 and t.distance_mm < 1]
        if not good:
            continue
        q = good[0].arm_joints
        approach = {}
        lower, upper = robot.body_limits
        for j, (name, kind) in enumerate(zip(robot.body_joint_names, robot.body.joint_types, strict=True)):
            step = rng.uniform(-20, 20) if kind == "revolute" else rng.uniform(-0.15, 0.15) / math.sqrt(2)
            scale = 180 / math.pi if kind == "revolute" else 1.0
            lo, hi = lower[j] * scale, upper[j] * scale
            approach[name] = float(np.clip(q[name] + step, lo, hi))
        problems.append(cube_problem(x, y, approach))
    bests = [r.best for r in gt.solve_many(problems, trials=trials, seed=seed)]
    return {"solved": sum(b.distance_mm < 1 and b.collisions == 0 for b in bests), "tried": len(problems)}


def random_check(n: int, trials: int, seed: int = 11) -> dict:
    """Random reachable problems: a random configuration's gripper points are the object's two
    points (no object, no table; floor and self-collision as always), listed in a random order."""
    robot, _ = robot_and_ik("manus")
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    gen = torch.Generator().manual_seed(seed)
    problems = []
    for k in range(n):
        q = lo + (hi - lo) * torch.rand(1, len(lo), generator=gen, dtype=torch.float64)
        pts = robot.gripper_points(q)[0].tolist()
        if k % 2:
            pts = pts[::-1]
        problems.append(GraspProblem.from_mapping({"name": f"random{k}", "robot": "manus", "points": pts},
                                                  f"<random {k}>"))
    bests = [r.best for r in gt.solve_many(problems, trials=trials, seed=seed)]
    return {"solved": sum(b.distance_mm < 5 and b.alignment > 0.999 for b in bests), "tried": n}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--every", type=int, default=8, help="baselines on 1 position in k")
    ap.add_argument("--out", type=Path, default=Path("reports"))
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    report = run_manus(ManusCfg(runs=args.runs, every=args.every), args.out)
    report.seconds = time.perf_counter() - t0
    appr = approach_check(report.results, trials=8)
    rand = random_check(40, trials=8)
    checks = [*report.checks,
              (f"approach: {appr['solved']}/{appr['tried']} positions d < 1 mm and collision-free >= 99 %",
               appr["solved"] >= 0.99 * max(appr["tried"], 1)),
              (f"random reachable: {rand['solved']}/{rand['tried']} d < 5 mm, alignment > 0.999 >= 95 %",
               rand["solved"] >= 0.95 * rand["tried"])]
    command = (f"python benchmarks/manus_protocol.py --runs {args.runs} --every {args.every} "
               f"--threads {torch.get_num_threads()}")
    lines = [report.markdown(command), "## This project's checks (issue 10)", "",
             f"- Approach (a collision-free protocol solution moved by up to 0.15 m and 20 degrees): "
             f"{appr['solved']}/{appr['tried']} positions solved (best of 8 learners, d < 1 mm, collision-free).",
             f"- Random reachable problems: {rand['solved']}/{rand['tried']} solved (best of 8 learners, d < 5 mm, "
             "alignment > 0.999).", "", "## Targets", "", *[f"- {'met' if ok else 'MISSED'}: {w}" for w, ok in checks],
             ""]
    path = atomic_write_text(args.out / "manus_protocol.md", "\n".join(lines))
    print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
