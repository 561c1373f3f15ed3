"""Every solver on the same problems, in one run: the paper's SRV loop (default and ``solver=paper``),
CMA-ES and damped least squares, behind the same ``gt.solve`` (same result, same float64 errors).

Sections (every wall time is a whole ``gt.solve`` call, median per problem):

1. random reachable hand problems (``gt.random_reachable_problem``, 2-5 fingers), 20 trials each,
   with the default's additions turned off one at a time (its ablations);
2. the Table 2 tasks (glass3, glass4, videotape5), 20 trials, ``seeds`` seeds;
3. noisy sensing: block5 and glass4 at each sigma_n, 2000 observations per trial: the noise
   presets (``noise=sigma...``: a = 20, s(r_hat) scale 0.5) against CMA-ES with the same reward,
   noise and budget; the true error (float64, from the reported configuration), median over
   trials, and the paper's a = 1 for reference;
4. the arm environments env1 and env2 (R3, obstacles), 16 trials, ``arm_seeds`` seeds:
   collision-free success (FCL) and wall time;
5. the MANUS cube protocol on ``manus_positions`` of the 64 positions, ``manus_runs`` learners each;
6. ``gt.solve_many`` throughput: ``many`` random reachable hand problems x 4 trials as one
   vectorised search (the default solver), problems per second to < 1 mm.

Targets (``checks``): the default solver solves >= 99 % of the random hand problems to < 1 mm
with a median wall time <= 1.5x that of ``solver=dls``; under noise (sigma_n = 0.2) its median true
error is < 3 mm on block5 and glass4; ``gt.solve_many`` solves >= 200 random hand problems per
second to < 1 mm (>= 99 % of them).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.experiments.report import ExperimentReport, arm_cell, batch_cell, progress, require
from graspnet_torch.paths import configs_dir
from graspnet_torch.settings import setting
from graspnet_torch.solver.config import DEFAULT_TRIALS, paper_protocol
from graspnet_torch.srv import SigmaCfg, SRVNetCfg
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.manus import cube_problem, protocol_positions

__all__ = ["SolversCfg", "run_solvers"]

SOLVED_PCT = 99.0
RATIO_VS_DLS = 1.5
NOISE_MM = 3.0
MANY_PER_S = 200.0
POINT = {"contact_model": "point"}  # the paper's tasks in the paper's contact model (the surface model: `contact`)
HAND = {"srv (default)": {}, "solver=paper": paper_protocol(), "cmaes": {"method": "cmaes"},
        "dls": {"method": "dls", "max_iterations": 100}}
ABLATIONS = {  # the additions one at a time
             "srv, no whole polish (polish.mode=fingers)": {"polish": {"mode": "fingers"}},
             "srv, no batch stop (stop=null)": {"stop": None},
             "srv, polish after the loop only (polish.from_r=null)": {"polish": {"from_r": None}}}


def _median_ms(x: list[float]) -> float:
    return float(np.median(x)) * 1000


def random_hand(n: int, trials: int, variants: dict[str, dict]) -> tuple[str, dict]:
    robot = gt.load_robot("hand")
    problems = [gt.random_reachable_problem(robot, seed) for seed in range(n)]
    for p in problems:  # warm-up: every finger set's kernels, shared by every solver, built once
        for cfg in variants.values():
            gt.solve(p, trials=2, seed=0, solver={**cfg, "max_iterations": 2})
    err = {k: [] for k in variants}
    wall = {k: [] for k in variants}
    its = {k: [] for k in variants}
    for k, p in progress(list(enumerate(problems)), desc="solvers: random hand problems", unit="problem"):
        order = list(variants) if k % 2 == 0 else list(variants)[::-1]  # drifts of a shared machine hit all alike
        for name in order:
            t0 = time.perf_counter()
            res = gt.solve(p, trials=trials, seed=k, solver=variants[name])
            wall[name].append(time.perf_counter() - t0)
            err[name].append(res.total_error_mm)
            its[name].append(res.best.iterations)
    fingers = np.array([len(p.contacts) for p in problems])
    base = np.median(wall["dls"])
    rows = []
    for name in variants:
        e = np.asarray(err[name])
        per = " / ".join(f"{np.mean(e[fingers == f] < 1) * 100:.0f}" for f in range(2, 6))
        rows.append([name, f"{np.mean(e < 1) * 100:.1f}", f"{np.mean(e < 10) * 100:.1f}", per, f"{np.median(e):.2g}",
                     f"{np.median(its[name]):g}", f"{_median_ms(wall[name]):.1f}",
                     f"{np.median(wall[name]) / base:.2f}"])
    text = (f"#### Random reachable hand problems\n\n{n} problems (2-5 fingers: "
            f"{' / '.join(str(int((fingers == f).sum())) for f in range(2, 6))}), {trials} trials each, seed k for "
            f"problem k.\n\n" + markdown_table(["solver", "< 1 mm %", "< 10 mm %", "< 1 mm % by 2/3/4/5 fingers",
                                             "median error mm", "best trial's iterations (median)",
                                             "median wall ms", "wall vs dls"], rows))
    solved = float(np.mean(np.asarray(err["srv (default)"]) < 1) * 100)
    ratio = float(np.median(wall["srv (default)"]) / base)
    return text, {"solved": solved, "ratio": ratio}


def table2(seeds: int) -> str:
    rows = []
    for task in progress(("glass3", "glass4", "videotape5"), desc="solvers: Table 2 tasks", unit="task"):
        for name, cfg in HAND.items():
            err, wall = [], []
            for s in range(seeds):
                t0 = time.perf_counter()
                res = gt.solve(task, trials=DEFAULT_TRIALS, seed=s, solver={**POINT, **cfg})
                wall.append(time.perf_counter() - t0)
                err.append(res.total_error_mm)
            e = np.asarray(err)
            rows.append([task, name, f"{np.mean(e < 1) * 100:.0f}", f"{np.median(e):.2g}", f"{e.max():.2g}",
                         f"{_median_ms(wall):.0f}"])
    return (f"#### Table 2 tasks\n\n{DEFAULT_TRIALS} trials, seeds 0-{seeds - 1}; the best trial of each solve; the "
            "paper's point contact model (`solver.contact_model=point`; the default surface model: the experiment "
            "`contact`).\n\n"
            + markdown_table(["task", "solver", "< 1 mm %", "median error mm", "worst mm", "median wall ms"], rows))


def noise(trials: int, levels: tuple[float, ...]) -> tuple[str, dict]:
    from omegaconf import OmegaConf

    rows, at = [], {}
    for sigma in progress(levels, desc="solvers: noise levels", unit="level"):
        preset = OmegaConf.load(configs_dir() / "noise" / f"sigma{sigma:g}.yaml")  # the preset noise=sigma...
        a, scale = float(preset.reward.a), float(preset.srv.sigma.scale)
        solver = {**POINT, "threshold": None, "polish": {"mode": preset.solver.polish.mode}, "max_iterations": 2000,
                  "history": False}
        variants = {f"srv, preset (a = {a:g}, scale {scale:g})": (gt.RewardCfg(a=a), SRVNetCfg(
                        sigma=SigmaCfg(scale=scale)), solver),
                    f"cmaes (a = {a:g})": (gt.RewardCfg(a=a), None, {**solver, "method": "cmaes"}),
                    "srv, the paper's a = 1": (gt.RewardCfg(a=1.0), None, solver)}
        for task in ("block5", "glass4"):
            for name, (reward, srv, cfg) in variants.items():
                t0 = time.perf_counter()
                res = gt.solve(task, trials=trials, seed=0, noise=sigma, reward=reward, srv=srv, solver=cfg)
                wall = time.perf_counter() - t0
                e = np.array([t.total_error_mm for t in res.trials])
                rows.append([f"{sigma:g}", task, name, f"{np.median(e):.2f}", f"{np.percentile(e, 90):.2f}",
                             f"{wall:.1f}"])
                if name.startswith("srv, preset"):
                    at[sigma, task] = float(np.median(e))
    text = (f"#### Noisy sensing\n\n{trials} trials, 2000 observations each, seed 0; true error of every trial's "
            "reported configuration (float64), median and 90th percentile over trials.\n\n"
            + markdown_table(["sigma_n", "task", "solver", "median error mm", "p90 mm", "wall s"], rows))
    return text, at


def arm(seeds: int) -> str:
    variants = {"srv (default)": {}, "solver=paper": paper_protocol(), "cmaes": {"method": "cmaes"},
                "dls": {"method": "dls"}}
    rows = []
    for env in progress(("env1", "env2"), desc="solvers: arm", unit="env"):
        for name, cfg in variants.items():
            cell = arm_cell(env, seeds, {**POINT, **cfg})
            rows.append([env, name, f"{cell.ok}/{seeds}", f"{np.median(cell.error_mm):.2g}",
                         f"{np.median(cell.wall_s):.2f}"])
    return (f"#### Arm among obstacles (R3)\n\n16 trials, seeds 1000-{999 + seeds}, the point contact model; "
            "success = the best trial is "
            "collision-free (FCL) with total error < 1 mm.\n\n"
            + markdown_table(["environment", "solver", "success", "median error mm", "median wall s"], rows))


def manus(positions: int, runs: int) -> str:
    grid = protocol_positions()[:: 64 // positions][:positions]
    problems = [cube_problem(x, y) for x, y in grid]
    variants = {"srv (robot defaults), every learner to its stop": {"stop": None}, "srv (default)": {},
                "cmaes": {"method": "cmaes"}, "dls": {"method": "dls"}}
    rows = []
    for name, cfg in progress(list(variants.items()), desc="solvers: MANUS", unit="solver"):
        cell = batch_cell(problems, runs, cfg)
        results, d, co, wall = cell.results, cell.distance_mm, cell.collisions, cell.wall_s
        best_ok = np.mean([r.best.distance_mm < 1 and r.best.collisions == 0 for r in results]) * 100
        rows.append([name, f"{best_ok:.0f}", f"{np.mean((d < 1) & (co == 0)) * 100:.0f}", f"{np.median(d):.2g}",
                     f"{wall / len(problems):.2f}"])
    return (f"#### MANUS\n\n{len(problems)} of the protocol's 64 cube positions x {runs} learners "
            "(gt.solve_many, seed 0); solved = d < 1 mm, collision-free (FCL).\n\n"
            + markdown_table(["solver", "problems solved (best trial) %", "learners solved %", "median d mm",
                            "wall s per problem"], rows))


def many(n: int, trials: int) -> tuple[str, dict]:
    robot = gt.load_robot("hand")
    problems = [gt.random_reachable_problem(robot, 10_000 + k) for k in range(n)]
    gt.solve_many(problems[:8], trials=trials, seed=0)  # warm-up
    t0 = time.perf_counter()
    results = gt.solve_many(problems, trials=trials, seed=0)
    wall = time.perf_counter() - t0
    e = np.array([r.total_error_mm for r in results])
    per_s = n / wall
    solved = float(np.mean(e < 1) * 100)
    text = (f"#### gt.solve_many\n\n{n} random reachable hand problems (2-5 fingers) x {trials} trials as one "
            f"vectorised search (default solver, seed 0): {wall:.2f} s, **{per_s:.0f} problems/s**; best trial "
            f"< 1 mm: {solved:.1f} % (median {np.median(e):.2g} mm, worst {e.max():.3g} mm).")
    return text, {"per_s": per_s, "solved": solved}


@dataclass(frozen=True)
class SolversCfg:
    """``+experiment=solvers``."""

    problems: int = setting(100, lo=4, hi=100_000)  # random reachable hand problems
    trials: int = setting(DEFAULT_TRIALS, lo=1, hi=10_000)  # gt.solve's
    seeds: int = setting(5, lo=1, hi=1000)  # per Table 2 task
    arm_seeds: int = setting(5, lo=1, hi=1000)
    manus_positions: int = setting(16, lo=1, hi=64)
    manus_runs: int = setting(30, lo=1, hi=10_000)
    noise_trials: int = setting(DEFAULT_TRIALS, lo=1, hi=10_000)
    noise_levels: tuple[float, ...] = setting((0.05, 0.1, 0.2), lo=0.0, hi=10.0)
    many: int = setting(1000, lo=8, hi=1_000_000)  # gt.solve_many's problems

    def __post_init__(self) -> None:
        presets = sorted(p.stem.removeprefix("sigma") for p in (configs_dir() / "noise").glob("sigma*.yaml"))
        require(len(self.noise_levels) > 0 and all((configs_dir() / "noise" / f"sigma{s:g}.yaml").is_file()
                                                   for s in self.noise_levels),
                f"experiments.solvers.noise_levels: expected levels with a noise preset ({', '.join(presets)}; "
                f"configs/noise/), got {list(self.noise_levels)}")


def run_solvers(cfg: SolversCfg, out: Path) -> ExperimentReport:
    """Every section (see the module's docstring), with the targets as ``checks``."""
    sections = []
    text, hand = random_hand(cfg.problems, cfg.trials, {**HAND, **ABLATIONS})
    sections.append(text)
    sections += [table2(cfg.seeds), arm(cfg.arm_seeds), manus(cfg.manus_positions, cfg.manus_runs)]
    text, noisy = noise(cfg.noise_trials, cfg.noise_levels)
    sections.append(text)
    text, batch = many(cfg.many, 4)
    sections.append(text)
    top = max(cfg.noise_levels)
    checks = [(f"default solver: {hand['solved']:.1f} % of random hand problems < 1 mm >= {SOLVED_PCT:g} %",
               hand["solved"] >= SOLVED_PCT),
              (f"default solver: median wall {hand['ratio']:.2f}x solver=dls <= {RATIO_VS_DLS:g}x",
               hand["ratio"] <= RATIO_VS_DLS),
              *((f"noise preset, sigma_n = {top:g}, {task}: median true error {noisy[top, task]:.2f} mm "
                 f"< {NOISE_MM:g} mm", noisy[top, task] < NOISE_MM) for task in ("block5", "glass4")),
              (f"gt.solve_many: {batch['per_s']:.0f} problems/s >= {MANY_PER_S:g}, {batch['solved']:.1f} % < 1 mm "
               f">= {SOLVED_PCT:g} %", batch["per_s"] >= MANY_PER_S and batch["solved"] >= SOLVED_PCT)]
    numbers = {"random hand/default solved %": hand["solved"], "many/solved %": batch["solved"],
               **{f"noise {s:g}/{task}/median mm": v for (s, task), v in noisy.items()}}
    timings = {"random hand/default wall vs dls": hand["ratio"], "many/problems per second": batch["per_s"]}
    return ExperimentReport("solvers", "Solvers side by side: the paper's loop, CMA-ES, damped least squares",
                            "The paper compares its method with no other solver; this compares every solver here on "
                            "the same problems, the paper's protocol (`solver=paper`) included. Wall times are whole "
                            "`gt.solve` calls; they vary from run to run.\n\n" + "\n\n".join(sections),
                            tables=["Solvers"], numbers=numbers, timings=timings, checks=checks)
