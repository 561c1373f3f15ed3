"""Summarize a Hydra sweep of solve_grasp.py: a table (CSV and markdown) and a plot of the metrics
against the swept parameters.

    python scripts/solve_grasp.py -m hydra/launcher=joblib noise=none,sigma0.05,sigma0.1,sigma0.2 seed=0,1
    python scripts/summarize_sweep.py multirun/solve_grasp/<date>   # -> summary.csv, summary.md, summary.png

Exit status: 0 when written, 2 when the folder holds no sweep (one line on stderr, nothing written).
"""

from __future__ import annotations

import argparse
import sys

from graspnet_torch.errors import GraspnetError, say
from graspnet_torch.jobs.summarize_sweep import summarize_sweep


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep", help="the sweep folder (hydra.sweep.dir of a -m run)")
    ap.add_argument("--out", default=None, help="folder for the summary (default: the sweep folder)")
    args = ap.parse_args()
    try:
        paths = summarize_sweep(args.sweep, args.out)
    except GraspnetError as exc:
        say(f"error: {exc}")
        return 2
    print("\n".join(f"wrote {p}" for p in paths.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
