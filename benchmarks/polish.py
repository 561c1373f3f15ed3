"""Levenberg-Marquardt with the analytic Jacobian against forward differences, side by side, and
``gt.solve_many``'s throughput on random reachable hand problems.

    python benchmarks/polish.py [--part all|step|solve_many] [--problems 1000] [--trials 4]
                                [--baseline-per-s X] [--threads 1] [--check]

``step``: the whole polish's model (the shipped ``hand``: palm pose + the contact fingers' joints,
``HandEnvironment.whole_tips``) on the same problems and the same random starts, at three batch
sizes (one problem x 20 trials, as ``gt.solve``; 64 and 250 problems x 4 trials, as ``gt.solve_many``),
2-5 fingers, and the whole hand (every problem with 5 fingers: m = 6 + 20 = 26) at each:
the time per evaluated Levenberg-Marquardt step (the fastest of 5 interleaved rounds; rows
refused at the largest damping are not evaluated again) with the analytic
Jacobian (one model evaluation per step) and with forward differences (m + 1 evaluations of the
fingertips per step, the previous implementation's Jacobian, built here from the public
kinematics), every row running every step,
and the fraction of rows each lands below 1 mm. Target: the analytic step >= 3x faster.
A step of a few rows is bound by the number of torch ops, not by arithmetic: there the m + 1
forward-difference evaluations cost about what one evaluation does, and the analytic Jacobian's
longer program (positions and Jacobian columns) gains little; the gain grows with the batch.

``solve_many``: ``gt.solve_many`` (public API only, so the script runs against earlier commits
too) on ``--problems`` random reachable hand problems (``gt.random_reachable_problem(robot,
10_000 + k)``, 2-5 fingers) x ``--trials`` trials, default solver, seed 0: problems per second,
the fraction whose best trial is below 1 mm and the fraction that succeeded. Targets: >= 99.5 %
below 1 mm and, given the previous commit's rate (``--baseline-per-s``, measured with this
script), >= 2x its problems per second.
"""

from __future__ import annotations

import argparse
import sys
import time

import torch

import graspnet_torch as gt
from graspnet_torch.benchmarking import check_targets, time_interleaved
from graspnet_torch.fcnn import load_finger_ik

STEP_TARGET = 3.0
MANY_TARGET = 2.0
SOLVED_PCT = 99.5
H = 1e-7  # the previous implementation's forward-difference step


def step_part(iterations: int) -> tuple[list[tuple[str, bool]], list[str]]:
    from graspnet_torch.least_squares import levenberg_marquardt
    from graspnet_torch.robot.fingers import FingerKernel
    from graspnet_torch.robot.transforms import transform_points
    from graspnet_torch.solver import SolverCfg
    from graspnet_torch.solver.api import build_environment

    robot = gt.load_robot("hand")
    ik = load_finger_ik(robot)
    checks, lines = [], []
    for P, runs, fingers in ((1, 20, None), (64, 4, None), (250, 4, None), (1, 20, 5), (64, 4, 5), (250, 4, 5)):
        problems = [gt.random_reachable_problem(robot, 20_000 + k, fingers) for k in range(P)]
        what = f"{P} x {runs} rows{', whole hand (5 fingers)' if fingers else ''}"
        env = build_environment(robot, problems if P > 1 else problems[0], ik, SolverCfg(), runs=runs)
        F, j = len(env.fingers), robot.joints_per_finger
        kernel = FingerKernel([robot.fingers[f].chain for f in env.fingers], width=j)
        base = torch.stack([torch.as_tensor(robot.fingers[f].base_in_palm) for f in env.fingers])
        mask = None if env.mask is None else env.mask.to(torch.float64).cpu().unsqueeze(-1)

        def tips(x: torch.Tensor, rows: torch.Tensor, env=env, kernel=kernel, base=base, mask=mask, F=F, j=j):
            """The fingertips alone (the previous implementation's model): (B, m) -> (B, 3F)."""
            R, t = env.palm_frame(x[:, : env.n])
            local = kernel.position(x[:, env.n:].reshape(-1, F, j))
            in_palm = transform_points(base[:, :3, :3], base[:, :3, 3], local)
            p = transform_points(R.unsqueeze(1), t.unsqueeze(1), in_palm)
            return (p if mask is None else p * mask[rows]).reshape(x.shape[0], -1)

        def forward_differences(x: torch.Tensor, rows: torch.Tensor, tips=tips):
            b, m = x.shape
            shifted = torch.cat([x.unsqueeze(1), x.unsqueeze(1) + H * torch.eye(m, dtype=x.dtype)], 1).reshape(-1, m)
            v = tips(shifted, rows.repeat_interleave(m + 1)).reshape(b, m + 1, -1)
            return v[:, 0], ((v[:, 1:] - v[:, :1]) / H).transpose(1, 2)

        T = P * runs
        x0 = env.random_whole(T, torch.Generator().manual_seed(0))
        lo, hi = env.whole_bounds()
        goal = env.contacts64.reshape(-1) if mask is None else (env.contacts64 * mask).reshape(T, 3 * F)
        models = {"analytic": env.whole_tips, "forward differences": forward_differences}
        for name, model in models.items():  # the same answer: the Jacobians differ by ~1e-7
            out = levenberg_marquardt(model, goal, x0, lo, hi, iterations)
            lines.append(f"{what}, {name:20s}: {float((out.err < 1e-3).float().mean()) * 100:5.1f} % of "
                         f"rows < 1 mm after {iterations} steps")
        calls = {}
        for name, model in models.items():  # the steps each run evaluates (rows stalled at lam_max are not)
            count = [0]

            def counted(x, rows, model=model, count=count):
                count[0] += 1
                return model(x, rows)

            levenberg_marquardt(counted, goal, x0, lo, hi, iterations)
            calls[name] = count[0] - 1  # the first evaluation is the start's
        fns = [lambda model=model, problem=(goal, x0, lo, hi): levenberg_marquardt(model, *problem, iterations)
               for model in models.values()]
        walls = time_interleaved(fns, min_time=1.0, rounds=5)
        best = {name: t / calls[name] for name, t in zip(models, walls, strict=True)}
        ratio = best["forward differences"] / best["analytic"]
        m = x0.shape[1]
        lines.append(f"{what} (m = {m}, {calls['analytic']} steps): per step analytic "
                     f"{best['analytic'] * 1e3:.2f} ms, forward differences "
                     f"{best['forward differences'] * 1e3:.2f} ms: {ratio:.2f}x faster")
        checks.append((f"LM step {what}: analytic {ratio:.2f}x faster than forward differences >= "
                       f"{STEP_TARGET:g}x", ratio >= STEP_TARGET))
    return checks, lines


def solve_many_part(n: int, trials: int, baseline: float | None) -> tuple[list[tuple[str, bool]], list[str]]:
    robot = gt.load_robot("hand")
    problems = [gt.random_reachable_problem(robot, 10_000 + k) for k in range(n)]
    gt.solve_many(problems[:8], trials=trials, seed=0)  # warm-up: kernels, checkpoint
    t0 = time.perf_counter()
    results = gt.solve_many(problems, trials=trials, seed=0)
    wall = time.perf_counter() - t0
    per_s = n / wall
    below = sum(r.best.total_error_mm < 1 for r in results) / n * 100
    success = sum(bool(r.success) for r in results) / n * 100
    lines = [f"gt.solve_many: P = {n} problems x T = {trials} trials, {torch.get_num_threads()} thread(s): "
             f"{wall:.1f} s, {per_s:.1f} problems/s; best trial < 1 mm: {below:.1f} %; succeeded: {success:.1f} %"]
    checks = [(f"gt.solve_many: {below:.1f} % < 1 mm >= {SOLVED_PCT:g} %", below >= SOLVED_PCT)]
    if baseline is not None:
        ratio = per_s / baseline
        lines.append(f"gt.solve_many: {per_s:.1f} problems/s vs {baseline:.1f} at the baseline: {ratio:.2f}x")
        checks.append((f"gt.solve_many {ratio:.2f}x the baseline's problems/s >= {MANY_TARGET:g}x",
                       ratio >= MANY_TARGET))
    return checks, lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("all", "step", "solve_many"), default="all")
    ap.add_argument("--iterations", type=int, default=30, help="LM steps per timed run (step part)")
    ap.add_argument("--problems", type=int, default=1000)
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--baseline-per-s", type=float, default=None,
                    help="the previous commit's gt.solve_many problems/s (this script's solve_many part)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    if args.baseline_per_s is not None and args.baseline_per_s <= 0:
        ap.error("--baseline-per-s must be positive")
    torch.set_num_threads(args.threads)
    print(f"torch.get_num_threads() = {torch.get_num_threads()}", flush=True)
    checks, lines = [], []
    if args.part in ("all", "step"):
        c, text = step_part(args.iterations)
        checks, lines = checks + c, lines + text
        print("\n".join(text), flush=True)
    if args.part in ("all", "solve_many"):
        c, text = solve_many_part(args.problems, args.trials, args.baseline_per_s)
        checks, lines = checks + c, lines + text
        print("\n".join(text), flush=True)
    return check_targets(checks, args.check)


if __name__ == "__main__":
    sys.exit(main())
