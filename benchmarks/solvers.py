"""Every solver on the same problems, in one run: the paper's SRV loop (default and ``solver=paper``),
CMA-ES and damped least squares, behind the same ``gt.solve`` (the experiment ``solvers`` of
:mod:`graspnet_torch.experiments`, whose docstring lists the sections and the targets).

    python benchmarks/solvers.py [--problems 100] [--quick] [--check] [--out reports/solvers.md]

``--check`` exits 1 when a target is missed; ``--quick`` is the reduced protocol of
``make reproduce-quick`` (a smoke run: its throughput is not the target's).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from graspnet_torch.benchmarking import check_targets
from graspnet_torch.experiments import SolversCfg, run_solvers
from graspnet_torch.experiments.report import quick_settings
from graspnet_torch.io import atomic_write_text
from graspnet_torch.jobs.reproduce import shipped_experiments


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=100)
    ap.add_argument("--quick", action="store_true", help="the reduced protocol (a smoke run)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("reports/solvers.md"))
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch threads: {torch.get_num_threads()}")
    cfg = quick_settings(SolversCfg, {**shipped_experiments()["solvers"], "problems": args.problems}, args.quick)
    t0 = time.perf_counter()
    report = run_solvers(cfg, args.out.parent)
    report.seconds = time.perf_counter() - t0
    command = f"python benchmarks/solvers.py --problems {cfg.problems}{' --quick' if args.quick else ''}"
    path = atomic_write_text(args.out, report.markdown(command, quick=args.quick, mismatches=False))
    print(f"wrote {path} ({report.seconds / 60:.1f} min)")
    return check_targets(report.checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
