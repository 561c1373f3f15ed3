"""The paper's Table 2 protocol for the HCNN (and Fig. 4), with its target checked.

The experiment ``table2`` (:mod:`graspnet_torch.experiments.table2`, also
``python scripts/reproduce.py +experiment=table2``): per task 20 single-trial runs after the
paper's time budgets and iteration counts, beside the paper's numbers, then a larger budget.

    python benchmarks/hcnn_table2.py [--trials 20] [--out reports/table2.md] [--check]

``--check`` exits 1 when a task's mean error after the paper's iteration count is above the paper's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from graspnet_torch.benchmarking import check_targets
from graspnet_torch.experiments import Table2Cfg, run_table2
from graspnet_torch.io import atomic_write_text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--out", type=Path, default=Path("reports/table2.md"))
    ap.add_argument("--threads", type=int, default=1)  # README "Threads"
    ap.add_argument("--check", action="store_true", help="exit 1 when a task's mean error is above the paper's")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    report = run_table2(Table2Cfg(trials=args.trials), args.out.parent)
    report.seconds = time.perf_counter() - t0
    atomic_write_text(args.out, report.markdown(f"python benchmarks/hcnn_table2.py --trials {args.trials} "
                                                f"--threads {torch.get_num_threads()}"))
    print(f"wrote {args.out}")
    return check_targets(report.checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
