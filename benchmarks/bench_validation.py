"""What the validation layer adds to a solve's start-up: the command line run with its checks
(overrides typed, config composed once more and validated, problem, output path, memory) against
the same job started by Hydra without them, as whole processes, side by side in one run.

    python benchmarks/bench_validation.py [--repeats 7] [--check]

The job without the checks is the same script with GRASPNET_TORCH_NO_PRECHECK=1 (for this
benchmark only; the job then still validates its composed config, which costs ~10 ms). Each
process solves glass3 with one trial and one iteration (no pictures, no TensorBoard), so its
wall time is start-up. ``--check`` exits 1 when the checks add 0.2 s or more (the target).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import torch

from graspnet_torch.paths import repo_root

TARGET_S = 0.2
ARGS = ["task=glass3", "trials=1", "max_iterations=1", "pictures=false", "tensorboard=false", "threads=1"]

def start_up(checked: bool, run_dir: str) -> float:
    env = {**os.environ, "GRASPNET_TORCH_NO_PRECHECK": "0" if checked else "1"}
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, str(repo_root() / "scripts" / "solve_grasp.py"), *ARGS,
                          f"hydra.run.dir={run_dir}"], capture_output=True, text=True, cwd=repo_root(), env=env)
    elapsed = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"the job failed: {res.stderr[-500:]}")
    return elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--check", action="store_true", help="exit 1 if the target is missed")
    args = ap.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        start_up(True, f"{tmp}/warm")  # file caches
        plain, checked = [], []
        for k in range(args.repeats):  # interleaved: drifts of a shared machine hit both alike
            plain.append(start_up(False, f"{tmp}/p{k}"))
            checked.append(start_up(True, f"{tmp}/c{k}"))
    p, c = statistics.median(plain), statistics.median(checked)
    added = c - p
    print(f"torch threads: {torch.get_num_threads()} (the job: threads=1); {args.repeats} processes each, median")
    print(f"solve_grasp start-up without the checks: {p:.3f} s")
    print(f"solve_grasp start-up with the checks:    {c:.3f} s  (ratio {c / p:.3f})")
    print(f"added by validation: {added:.3f} s (target < {TARGET_S} s): {'met' if added < TARGET_S else 'NOT met'}")
    if args.check and added >= TARGET_S:
        sys.exit(1)


if __name__ == "__main__":
    main()
