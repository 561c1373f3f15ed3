"""Which torch thread count to use by default: training, solving and kinematics, 1 vs 2 threads.

Each job runs with 1 thread, then 2 threads, alternating ``--rounds`` times; the best time of
each is printed with the ratio (2 threads / 1 thread; above 1: one thread is faster). On a
machine with other work running, two threads fight for the cores: that is the case this
measures. The defaults (``threads: 1`` in configs/train_fcnn.yaml and configs/solve_grasp.yaml,
``--threads 1`` in the benchmarks) come from it.

    python benchmarks/bench_threads.py [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.fcnn.train import FCNNTrainCfg, FingerTrainer


def _train(robot: gt.Robot) -> None:
    cfg = FCNNTrainCfg.from_mapping({"epochs": 8, "val_targets": 1000})
    trainer = FingerTrainer(robot.fingers["index"].chain, cfg, seed=0)
    for _ in range(cfg.epochs):
        trainer.epoch()


def _solve(problem: gt.GraspProblem) -> None:
    gt.solve(problem, trials=20, seed=0, max_iterations=300, solver={"threshold": None},
             threads=torch.get_num_threads())  # the count this round set (gt.solve's own default is 1)


def _kinematics(robot: gt.Robot) -> None:
    lo, hi = (torch.as_tensor(a, dtype=torch.float32) for a in robot.finger_limits)
    q = lo + (hi - lo) * torch.rand(100_000, *lo.shape, generator=torch.Generator().manual_seed(0))
    for _ in range(20):
        robot.fingertips_base_jacobian(q)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--check", action="store_true", help="exit 1 when 1 thread is over 3x slower than 2")
    args = ap.parse_args()
    checks = []
    robot = gt.load_robot("hand")
    problem = gt.GraspProblem.from_task("glass3")
    jobs = {"FCNN training (8 epochs, index)": lambda: _train(robot),
            "solve glass3 (20 trials x 300 it)": lambda: _solve(problem),
            "FK + Jacobian (20 x 100k hands)": lambda: _kinematics(robot)}
    print(f"{os.cpu_count()} CPU cores; load average {os.getloadavg()[0]:.2f}; best of {args.rounds} rounds")
    print(f"{'job':36s} {'1 thread s':>11s} {'2 threads s':>12s} {'2 / 1':>7s}")
    for name, job in jobs.items():
        best = {1: float("inf"), 2: float("inf")}
        for _ in range(args.rounds):
            for threads in (1, 2):
                torch.set_num_threads(threads)
                t0 = time.perf_counter()
                job()
                best[threads] = min(best[threads], time.perf_counter() - t0)
        print(f"{name:36s} {best[1]:11.2f} {best[2]:12.2f} {best[2] / best[1]:7.2f}", flush=True)
        # the default of 1 thread trades at most ~2x on an idle 2-core machine (the cores it leaves
        # unused) against the 10-90x that 2 threads lost on a busy one (docs/solvers.md, "Threads")
        checks.append((f"{name}: 1 thread {best[1]:.2f} s within 3x of 2 threads ({best[2]:.2f} s)",
                       best[1] <= 3 * best[2]))
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
