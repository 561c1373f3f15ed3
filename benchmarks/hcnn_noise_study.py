"""The paper's Fig. 3: learning the five-finger block grasp with a noisy reinforcement.

The experiment ``fig3`` (:mod:`graspnet_torch.experiments.fig3`, also
``python scripts/reproduce.py +experiment=fig3``): block5, sigma_n in {0, 0.05, 0.1, 0.2}, 2000
steps, 20 trials per level; the deterministic error of the configurations tried.

    python benchmarks/hcnn_noise_study.py [--trials 20] [--out reports] [--a 1] [--s linear] [--scale 3]

``--a``, ``--s`` and ``--scale`` replace the defaults of the reinforcement's slope (eq. 14) and of
s(r_hat) (eq. 11); ``benchmarks/hcnn_noise_tradeoff.py`` sweeps them. ``--check`` exits 1 when a
noise level does not learn (its error falls less than 3x).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from graspnet_torch.benchmarking import check_targets
from graspnet_torch.experiments import NoiseStudyCfg, run_noise_study
from graspnet_torch.io import atomic_write_text
from graspnet_torch.solver import RewardCfg
from graspnet_torch.srv import SigmaCfg


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--out", type=Path, default=Path("reports"))
    ap.add_argument("--a", type=float, default=RewardCfg.a, help="slope of r = 1 - tanh(a E)")
    ap.add_argument("--s", default=SigmaCfg.kind, choices=["linear", "quadratic"], help="form of s(r_hat)")
    ap.add_argument("--scale", type=float, default=SigmaCfg.scale, help="scale of s(r_hat)")
    ap.add_argument("--check", action="store_true", help="exit 1 when a noise level does not learn (error / 3)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    default = args.a == RewardCfg.a and args.s == SigmaCfg.kind and args.scale == SigmaCfg.scale
    flags = "" if default else f" --a {args.a:g} --s {args.s} --scale {args.scale:g}"
    t0 = time.perf_counter()
    report = run_noise_study(NoiseStudyCfg(trials=args.trials, steps=args.steps, a=args.a, s=args.s,
                                           scale=args.scale), args.out)
    report.seconds = time.perf_counter() - t0
    path = atomic_write_text(args.out / "noise_study.md",
                             report.markdown(f"python benchmarks/hcnn_noise_study.py --trials {args.trials}{flags}"))
    print(f"wrote {path}")
    return check_targets(report.checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
