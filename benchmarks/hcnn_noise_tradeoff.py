"""Can any setting of the paper's open choices meet the noise study's 2x target and Table 2 together?

The paper fixes the learning rates (0.01) but leaves open the slope a of the reinforcement
(r = 1 - tanh(a E), eq. 14/20) and the exploration function s(r_hat) (eq. 11). This sweeps them:
for each setting, the noise study on block5 (2000 steps, 20 trials, final error = mean over the
last 100 steps of the deterministic error of the configurations tried, median over trials) without
noise and at sigma_n = 0.2, on three seed sets; and the Table 2 iteration column (glass3 2000,
glass4 1000, videotape5 1000 iterations; 20 trials batched, reported configuration after 3
refinements, mean total error) against the paper's 3.1 / 5.1 / 6.9 mm.

    python benchmarks/hcnn_noise_tradeoff.py [--out reports/noise_tradeoff.md]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets
from graspnet_torch.io import atomic_write_text
from graspnet_torch.solver import SolverCfg
from graspnet_torch.solver.config import FingersCfg, RewardCfg
from graspnet_torch.srv import SigmaCfg, SRVNetCfg

# (a, s kind, s scale): the defaults first, then the settings that converge best without noise
# (large a), then those that come nearest the 2x target (little exploration at a ~ 1, or the
# quadratic s with a large scale).
SETTINGS = [(1.0, "linear", 3.0), (1.0, "linear", 1.0), (1.0, "linear", 1.5), (2.0, "linear", 1.0),
            (3.0, "linear", 2.0), (10.0, "linear", 0.5), (20.0, "linear", 0.5), (2.0, "quadratic", 8.0),
            (1.0, "quadratic", 30.0), (2.0, "quadratic", 10.0), (3.0, "quadratic", 7.0), (4.0, "quadratic", 5.0),
            (5.0, "quadratic", 5.0)]
TABLE2 = (("glass3", 2000, 3.1), ("glass4", 1000, 5.1), ("videotape5", 1000, 6.9))


def final_error_mm(srv: SRVNetCfg, reward: RewardCfg, sigma_n: float, seed: int, trials: int, steps: int) -> float:
    """Noise-study final error: median over trials of the mean error of the last 100 steps (mm)."""
    res = gt.solve("block5", trials=trials, seed=seed, noise=sigma_n, srv=srv, reward=reward,
                   solver=SolverCfg.paper(threshold=None, max_iterations=steps, fingers=FingersCfg(final_refine=0)))
    total = res.outcome.history["total"].double().numpy()  # (K, T) metres
    return float(np.median(total[-100:].mean(0))) * 1000


def table2_means_mm(srv: SRVNetCfg, reward: RewardCfg, trials: int) -> list[float]:
    """Mean total error of the reported configurations after the Table 2 iteration budgets (mm)."""
    out = []
    for task, iterations, _paper in TABLE2:
        res = gt.solve(task, trials=trials, seed=0, srv=srv, reward=reward,
                       solver=SolverCfg.paper(threshold=None, max_iterations=iterations, history=False))
        out.append(float(np.mean([t.total_error_mm for t in res.trials])))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--seeds", type=int, default=3, help="seed sets for the noise study")
    ap.add_argument("--out", default="reports/noise_tradeoff.md")
    ap.add_argument("--check", action="store_true", help="exit 1 when the default setting misses Table 2")
    args = ap.parse_args()
    torch.set_num_threads(1)
    seeds = range(args.seeds)
    rows = []
    started = time.perf_counter()
    for a, kind, scale in SETTINGS:
        srv, reward = SRVNetCfg(sigma=SigmaCfg(kind=kind, scale=scale)), RewardCfg(a=a)
        clean = [final_error_mm(srv, reward, 0.0, s, args.trials, args.steps) for s in seeds]
        noisy = [final_error_mm(srv, reward, 0.2, s, args.trials, args.steps) for s in seeds]
        t2 = table2_means_mm(srv, reward, args.trials)
        ratios = [n / c for c, n in zip(clean, noisy, strict=True)]
        converges = max(noisy) < 100 and max(clean) < 100  # the block starts ~500 mm away
        ok_ratio = converges and max(ratios) <= 2
        ok_t2 = all(m <= p for m, (_, _, p) in zip(t2, TABLE2, strict=True))
        rows.append((a, kind, scale, clean, noisy, ratios, t2, ok_ratio, ok_t2))
        print(f"a={a:g} s={kind} x{scale:g}: clean {np.round(clean, 1)} mm, sigma_n 0.2 {np.round(noisy, 1)} mm, "
              f"ratio {np.round(ratios, 2)}, Table 2 {np.round(t2, 2)} mm", flush=True)

    def fmt(v: list[float], d: int = 1) -> str:
        return " / ".join(f"{x:.{d}f}" for x in v)

    lines = ["# Noise study against Table 2: the open choices swept", "",
             f"`python benchmarks/hcnn_noise_tradeoff.py` ({time.perf_counter() - started:.0f} s). Paper learning "
             f"rates (0.01) throughout. Noise study: block5, {args.steps} steps, {args.trials} trials, seed sets "
             f"{', '.join(map(str, seeds))}; final error = mean over the last 100 steps of the deterministic "
             "error, median over trials. Table 2: iteration column (2000 / 1000 / 1000 iterations), "
             f"{args.trials} trials batched (seed 0), mean total error of the reported configurations; paper "
             "3.1 / 5.1 / 6.9 mm.", "",
             "| a | s(r_hat) | scale | final error, no noise (mm) | final error, sigma_n = 0.2 (mm) | ratio | "
             "2x met on every seed set | Table 2 means (mm) | Table 2 met |",
             "|---|---|---|---|---|---|---|---|---|"]
    for a, kind, scale, clean, noisy, ratios, t2, ok_ratio, ok_t2 in rows:
        lines.append(f"| {a:g} | {kind} | {scale:g} | {fmt(clean)} | {fmt(noisy)} | {fmt(ratios, 2)} | "
                     f"{'yes' if ok_ratio else 'no'} | {fmt(t2, 2)} | {'yes' if ok_t2 else 'no'} |")
    both = [r for r in rows if r[7] and r[8]]
    lines += ["", f"Settings meeting both: {len(both)} of {len(rows)}."]
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    default = rows[0]  # a = 1, linear s x 3: the defaults without noise
    return check_targets([(f"a = {default[0]:g}, {default[1]} s x {default[2]:g} (default): Table 2 means "
                           f"{fmt(default[6], 2)} mm at or below the paper's", bool(default[8]))], args.check)


if __name__ == "__main__":
    sys.exit(main())
