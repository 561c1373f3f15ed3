"""A sweep on one machine: hydra/launcher=joblib (jobs in parallel) against the basic launcher
(one after another), the same 8 jobs, side by side in one run.

    python benchmarks/sweep_launchers.py [--rounds 2] [--long] [--check]

The sweep: ``solve_grasp.py -m noise=none,sigma0.05,sigma0.1,sigma0.2 seed=0,1`` (glass3, 20 trials,
pictures and TensorBoard included), each job on one torch thread. Each round runs both launchers
in turn as whole commands (start-up and checks included); the best round of each counts.
Target (``--check`` exits 1 when missed): joblib at least 1.6x faster than basic.

What bounds the ratio on 2 cores: the basic launcher pays Python's start, the imports and the
checks once; joblib pays them in the parent and again in each worker (a fresh Python), and its
jobs share the machine's memory bandwidth with each other. The shorter the jobs, the more these
fixed costs weigh. ``--long`` also times the same sweep with longer jobs (``trials=200``), where
they weigh little (reported beside, not a target).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

from graspnet_torch.benchmarking import check_targets
from graspnet_torch.paths import repo_root

SWEEP = ["noise=none,sigma0.05,sigma0.1,sigma0.2", "seed=0,1"]
TARGET = 1.6


def run(launcher: str | None, folder: str, extra: tuple[str, ...] = ()) -> float:
    args = [sys.executable, str(repo_root() / "scripts" / "solve_grasp.py"), "-m", *SWEEP, *extra,
            f"hydra.sweep.dir={folder}"] + ([f"hydra/launcher={launcher}"] if launcher else [])
    t0 = time.perf_counter()
    res = subprocess.run(args, capture_output=True, text=True, cwd=repo_root())
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"the sweep failed ({launcher or 'basic'}): {res.stderr[-500:]}")
    n = sum(1 for _, _, files in os.walk(folder) for f in files if f == "result.json")
    if n != 8:
        raise SystemExit(f"the sweep wrote {n} results, not 8 ({launcher or 'basic'})")
    return wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--long", action="store_true", help="also the sweep with longer jobs (trials=200)")
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    print(f"{os.cpu_count()} CPU cores; load average {os.getloadavg()[0]:.2f}; 8 jobs, 1 torch thread each")
    ratios = {}
    for label, extra in [("the sweep", ())] + ([("longer jobs (trials=200)", ("trials=200",))] if args.long else []):
        best = {"basic": float("inf"), "joblib": float("inf")}
        with tempfile.TemporaryDirectory() as tmp:
            for r in range(args.rounds):
                for name in (("basic", "joblib") if r % 2 == 0 else ("joblib", "basic")):
                    wall = run(None if name == "basic" else name, os.path.join(tmp, f"{name}{r}"), extra)
                    best[name] = min(best[name], wall)
                    print(f"{label}, round {r + 1}: {name:6s} {wall:6.1f} s", flush=True)
        ratios[label] = best["basic"] / best["joblib"]
        print(f"{label}, best: basic {best['basic']:.1f} s, joblib {best['joblib']:.1f} s: joblib "
              f"{ratios[label]:.2f}x faster\n", flush=True)
    ratio = ratios["the sweep"]
    return check_targets([(f"joblib {ratio:.2f}x faster than basic >= {TARGET:g}x", ratio >= TARGET)], args.check)


if __name__ == "__main__":
    sys.exit(main())
