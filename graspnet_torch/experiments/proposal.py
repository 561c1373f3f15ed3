"""What the posture proposals cost and buy (beyond the paper): the proposal alone, the loop started
from it, the loop from random starts (the paper) and CMA-ES, on the same problems.

1. random reachable hand problems (2-5 fingers, seeds 50000 + k): the best of the K proposals
   with the FCNN's fingers and no iteration (no polish), then the default solver from the
   proposals (T = 2) and from random starts (T = 2 and T = 20), and CMA-ES (T = 20);
2. the Table 2 tasks (glass3, glass4, videotape5; objects, so the polish starts at r > 0.9): 20
   trials, seeds 0..``seeds``-1;
3. noisy sensing (sigma_n 0.2, the preset ``noise=sigma0.2``, 2000 observations, 20 trials) on
   block5 and glass4: the true error of every trial's reported configuration, and how many are
   clear of the object (FCL) and succeed (the preset's reward ignores collisions);
4. the arm among unknown obstacles (env1, env2, R3; the proposal never sees the obstacles): 16
   trials, seeds 1000..; collision-free success and the iterations every trial ran (mean);
5. the MANUS protocol (``manus_positions`` of its 64 cube positions x ``manus_runs`` learners,
   ``gt.solve_many``): mean d and the share of learners solved (d < 1 mm, collision-free) and the
   iterations they ran;
6. a third-party hand by config (TriFinger, ``examples/trifinger``), random reachable problems, as 1.

Iterations are loop iterations (CMA-ES: evaluations); wall times are one thread's. Every solve is in
the paper's point contact model (``solver.contact_model=point``; the default surface model, pads on the
object's surface: the experiment ``contact``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.experiments.report import ExperimentReport, arm_cell, batch_cell, progress
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.proposal import proposal_of
from graspnet_torch.robot import load_robot_cfg
from graspnet_torch.settings import setting
from graspnet_torch.solver import api
from graspnet_torch.solver.config import DEFAULT_TRIALS
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.proposals import proposals
from graspnet_torch.srv import SigmaCfg, SRVNetCfg
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.manus import cube_problem, protocol_positions

__all__ = ["ProposalExperimentCfg", "best_proposal_mm", "run_proposal"]

TARGETS = {"median_mm": 10.0, "p90_mm": 30.0, "t2_pct": 99.5, "noise_p90_mm": 10.0, "noise_median_mm": 1.0}


@dataclass(frozen=True)
class ProposalExperimentCfg:
    """``+experiment=proposal``."""

    problems: int = setting(200, lo=2, hi=100_000)  # random reachable hand problems (and TriFinger's: a quarter)
    seeds: int = setting(3, lo=1, hi=1000)  # per Table 2 task
    noise_trials: int = setting(DEFAULT_TRIALS, lo=1, hi=10_000)  # gt.solve's
    arm_seeds: int = setting(5, lo=1, hi=1000)
    manus_positions: int = setting(16, lo=1, hi=64)
    manus_runs: int = setting(10, lo=1, hi=1000)


def best_proposal_mm(robot: gt.Robot, problem: gt.GraspProblem) -> float:
    """The best of the robot's K proposals for a problem (within bounds, evaluated by its
    environment: a hand's fingers by the FCNN; no iteration), mm."""
    _robot, ik = api.robot_and_ik(problem.robot_cfg or robot.name)
    env = build_environment(robot, problem, ik, gt.SolverCfg(contact_model="point"))
    with torch.inference_mode():
        return float(env.evaluate(proposals(proposal_of(robot), env).config[0]).error.min()) * 1000


def _solver(start: str, **changes) -> gt.SolverCfg:
    return replace(gt.SolverCfg(), start=start, **{"contact_model": "point", **changes})  # the paper's tasks, its model


def _hand_rows(robot: gt.Robot, problems: list[gt.GraspProblem], label: str) -> tuple[str, dict]:
    alone = np.array([best_proposal_mm(robot, p) for p in problems])
    variants = {"proposal + loop, T = 2": (_solver("proposal"), 2), "random + loop, T = 2": (_solver("random"), 2),
                "random + loop, T = 20": (_solver("random"), 20), "cmaes, T = 20": (_solver("random",
                                                                                            method="cmaes"), 20)}
    rows = [["proposal alone (best of K, no iteration)", f"{np.mean(alone < 1) * 100:.1f}", f"{np.median(alone):.3g}",
             f"{np.percentile(alone, 90):.3g}", "0", "-"]]
    out = {"alone_median_mm": float(np.median(alone)), "alone_p90_mm": float(np.percentile(alone, 90))}
    for name, (cfg, trials) in variants.items():
        err, its, wall, ok = [], [], [], []
        for k, p in enumerate(progress(problems, desc=f"proposal: {label}: {name}", unit="problem")):
            t0 = time.perf_counter()
            r = gt.solve(p, trials=trials, seed=k, solver=cfg)
            wall.append(time.perf_counter() - t0)
            err.append(r.best.total_error_mm)
            its.append(r.best.iterations)
            ok.append(r.success and r.best.total_error_mm < 1)
        e = np.asarray(err)
        rows.append([name, f"{np.mean(ok) * 100:.1f}", f"{np.median(e):.3g}", f"{np.percentile(e, 90):.3g}",
                     f"{np.mean(its):.1f}", f"{np.median(wall) * 1000:.1f}"])
        out[f"{name}/solved_pct"] = float(np.mean(ok) * 100)
        out[f"{name}/mean_iterations"] = float(np.mean(its))
    table = markdown_table(["start", "solved < 1 mm %", "median mm", "p90 mm", "best trial's iterations (mean)",
                            "median wall ms"], rows)
    return table, out


def _table2(seeds: int) -> str:
    variants = {"proposal + loop": _solver("proposal"), "random + loop": _solver("random"),
                "cmaes": _solver("random", method="cmaes")}
    rows = []
    for task in progress(("glass3", "glass4", "videotape5"), desc="proposal: Table 2 tasks", unit="task"):
        for name, cfg in variants.items():
            err, its, wall, ok = [], [], [], []
            for s in range(seeds):
                t0 = time.perf_counter()
                r = gt.solve(task, trials=DEFAULT_TRIALS, seed=s, solver=cfg)
                wall.append(time.perf_counter() - t0)
                err.append(r.best.total_error_mm)
                its.append(np.mean([t.iterations for t in r.trials]))
                ok.append(r.success)
            rows.append([task, name, f"{np.mean(ok) * 100:.0f}", f"{np.median(err):.2g}", f"{np.mean(its):.0f}",
                         f"{np.median(wall) * 1000:.0f}"])
    return markdown_table(["task", "start", "success %", "median error mm", "iterations per trial (mean)",
                           "median wall ms"], rows)


def _noise(trials: int) -> tuple[str, dict]:
    from omegaconf import OmegaConf

    preset = OmegaConf.load(configs_dir() / "noise" / "sigma0.2.yaml")
    reward = gt.RewardCfg(a=float(preset.reward.a))
    srv = SRVNetCfg(sigma=SigmaCfg(scale=float(preset.srv.sigma.scale)))
    base = {"threshold": None, "polish": gt.PolishCfg(mode=preset.solver.polish.mode), "max_iterations": 2000,
            "history": False}
    variants = {"preset, proposal": (srv, _solver("proposal", **base)), "preset, random": (srv, _solver("random",
                                                                                                       **base)),
                "cmaes": (None, _solver("random", method="cmaes", **base))}
    rows, at = [], {}
    for task in progress(("block5", "glass4"), desc="proposal: noisy sensing", unit="task"):
        for name, (net, cfg) in variants.items():
            t0 = time.perf_counter()
            r = gt.solve(task, trials=trials, seed=0, noise=0.2, reward=reward, srv=net, solver=cfg)
            e = np.array([t.total_error_mm for t in r.trials])
            clear = np.mean([t.collisions == 0 for t in r.trials]) * 100
            rows.append([task, name, f"{np.median(e):.3g}", f"{np.percentile(e, 90):.3g}", f"{clear:.0f}",
                         f"{np.mean([t.success for t in r.trials]) * 100:.0f}", f"{time.perf_counter() - t0:.1f}"])
            at[task, name] = (float(np.median(e)), float(np.percentile(e, 90)))
    return markdown_table(["task", "start", "median true error mm", "p90 mm", "collision-free (FCL) %",
                           "success %", "wall s"], rows), at


def _arm(seeds: int) -> tuple[str, dict]:
    variants = {"proposal + loop": _solver("proposal"), "random + loop": _solver("random"),
                "cmaes": _solver("random", method="cmaes")}
    rows, at = [], {}
    for env in progress(("env1", "env2"), desc="proposal: arm", unit="env"):
        for name, cfg in variants.items():
            cell = arm_cell(env, seeds, cfg)
            rows.append([env, name, f"{cell.ok}/{seeds}", f"{np.mean(cell.iterations):.0f}",
                         f"{np.median(cell.wall_s):.2f}"])
            at[env, name] = (cell.ok, float(np.mean(cell.iterations)))
    return markdown_table(["environment", "start", "collision-free success", "iterations per trial (mean)",
                           "median wall s"], rows), at


def _manus(positions: int, runs: int) -> tuple[str, dict]:
    problems = [cube_problem(x, y) for x, y in protocol_positions()[:: 64 // positions][:positions]]
    variants = {"proposal + loop": _solver("proposal", stop=None), "random + loop": _solver("random", stop=None),
                "cmaes": _solver("random", method="cmaes", stop=None)}
    rows, at = [], {}
    for name, cfg in progress(list(variants.items()), desc="proposal: MANUS", unit="start"):
        cell = batch_cell(problems, runs, cfg)
        d, co, its, wall = cell.distance_mm, cell.collisions, cell.iterations, cell.wall_s
        solved = float(np.mean((d < 1) & (co == 0)) * 100)
        rows.append([name, f"{np.mean(d):.3g}", f"{solved:.0f}", f"{np.mean(its):.0f}", f"{wall / len(problems):.2f}"])
        at[name] = (float(np.mean(d)), solved, float(np.mean(its)))
    return markdown_table(["start", "mean d mm", "learners solved %", "iterations per learner (mean)",
                           "wall s per problem"], rows), at


def run_proposal(cfg: ProposalExperimentCfg, out: Path) -> ExperimentReport:
    hand = gt.load_robot("hand")
    hand_text, hand_at = _hand_rows(hand, [gt.random_reachable_problem(hand, 50_000 + k) for k in range(cfg.problems)],
                                    "random hand")
    table2_text = _table2(cfg.seeds)
    noise_text, noise_at = _noise(cfg.noise_trials)
    arm_text, arm_at = _arm(cfg.arm_seeds)
    manus_text, manus_at = _manus(cfg.manus_positions, cfg.manus_runs)
    tri = gt.Robot(load_robot_cfg(str(repo_root() / "examples" / "trifinger" / "trifinger.yaml")))
    tri_text, tri_at = _hand_rows(tri, [gt.random_reachable_problem(tri, 51_000 + k)
                                        for k in range(max(2, cfg.problems // 4))], "trifinger")
    body = "\n\n".join([
        " ".join(__doc__.split("\n\n")[0].split()),
        f"#### Random reachable hand problems\n\n{cfg.problems} problems.\n\n{hand_text}",
        f"#### Table 2 tasks\n\n{table2_text}",
        f"#### Noisy sensing (sigma_n = 0.2)\n\n{cfg.noise_trials} trials, 2000 observations, seed 0.\n\n{noise_text}",
        f"#### Arm among unknown obstacles (R3)\n\n{cfg.arm_seeds} seeds, 16 trials.\n\n{arm_text}",
        f"#### MANUS\n\n{cfg.manus_positions} positions x {cfg.manus_runs} learners (every learner to its own "
        f"stop).\n\n{manus_text}",
        f"#### TriFinger by config\n\n{max(2, cfg.problems // 4)} problems.\n\n{tri_text}", ""])
    checks = [
        (f"hand, proposal alone: median {hand_at['alone_median_mm']:.2f} mm <= {TARGETS['median_mm']:g}",
         hand_at["alone_median_mm"] <= TARGETS["median_mm"]),
        (f"hand, proposal alone: p90 {hand_at['alone_p90_mm']:.2f} mm <= {TARGETS['p90_mm']:g}",
         hand_at["alone_p90_mm"] <= TARGETS["p90_mm"]),
        (f"hand, proposal + loop, T = 2: {hand_at['proposal + loop, T = 2/solved_pct']:.1f} % < 1 mm >= "
         f"{TARGETS['t2_pct']:g} %", hand_at["proposal + loop, T = 2/solved_pct"] >= TARGETS["t2_pct"])]
    for task in ("block5", "glass4"):
        med, p90 = noise_at[task, "preset, proposal"]
        checks += [(f"noise 0.2, {task}, proposal: p90 true error {p90:.2f} mm <= {TARGETS['noise_p90_mm']:g}",
                    p90 <= TARGETS["noise_p90_mm"]),
                   (f"noise 0.2, {task}, proposal: median true error {med:.2f} mm <= {TARGETS['noise_median_mm']:g}",
                    med <= TARGETS["noise_median_mm"])]
    for env in ("env1", "env2"):
        (ok_p, it_p), (ok_r, it_r) = arm_at[env, "proposal + loop"], arm_at[env, "random + loop"]
        checks += [(f"{env}: proposal success {ok_p} >= random's {ok_r}", ok_p >= ok_r),
                   (f"{env}: proposal iterations {it_p:.0f} <= half of random's {it_r:.0f}", it_p <= it_r / 2)]
    (d_p, s_p, it_p), (d_r, s_r, it_r) = manus_at["proposal + loop"], manus_at["random + loop"]
    checks += [(f"MANUS: proposal mean d {d_p:.3g} mm <= random's {d_r:.3g}", d_p <= d_r),
               (f"MANUS: proposal solved {s_p:.0f} % >= random's {s_r:.0f} %", s_p >= s_r),
               (f"MANUS: proposal iterations {it_p:.0f} <= half of random's {it_r:.0f}", it_p <= it_r / 2)]
    numbers = {**{f"hand/{k}": v for k, v in hand_at.items()}, **{f"trifinger/{k}": v for k, v in tri_at.items()},
               **{f"noise/{t}/{n}/median mm": v[0] for (t, n), v in noise_at.items()},
               **{f"noise/{t}/{n}/p90 mm": v[1] for (t, n), v in noise_at.items()},
               **{f"manus/{n}/mean d mm": v[0] for n, v in manus_at.items()}}
    return ExperimentReport("proposal", "Posture proposals: what they cost and buy", body, numbers=numbers,
                            checks=checks)
