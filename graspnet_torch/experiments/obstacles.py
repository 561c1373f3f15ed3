"""The paper's section 6.3: the arm and hand among unknown obstacles.

``table3``: Tables 3 and 4 (the reinforcements R1-R4 in env1 and env2, ``runs`` independent
learners each), the one-way ANOVA of the successes' iteration counts with Bonferroni post-hoc
tests, CMA-ES from the same starts with the same R3, and Figs. 6, 8 and 9. ``fig10``: Fig. 10, the
posture among three obstacles.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.experiments.report import ExperimentReport, Figure, progress, require
from graspnet_torch.settings import setting
from graspnet_torch.solver import RewardCfg, SolverCfg
from graspnet_torch.solver.api import build_environment, robot_and_ik, trial_posture
from graspnet_torch.solver.cmaes import run_cmaes
from graspnet_torch.table import markdown_table
from graspnet_torch.viz import render_robot
from graspnet_torch.viz.plots import _plt
from graspnet_torch.viz.result import posture_panels

__all__ = ["PAPER", "REWARDS", "Fig10Cfg", "ObstaclesCfg", "anova", "cmaes_rows", "figures", "reward_cfg", "run_fig10",
           "run_tables", "tables"]

REWARDS = ("r1", "r2", "r3", "r4")
THRESHOLD = 0.99  # the paper's success: the reinforcement above it (SolverCfg.paper().threshold)
PAPER = {  # Tables 3 and 4: successes, failures (positioning, collision), mean and std of iterations
    "env1": {"r1": (26, 4, 22, 102, 126), "r2": (20, 10, 3, 430, 271), "r3": (22, 7, 6, 281, 259),
             "r4": (26, 4, 2, 310, 245)},
    "env2": {"r1": (25, 5, 24, 120, 161), "r2": (8, 22, 4, 454, 266), "r3": (22, 7, 2, 273, 228),
             "r4": (16, 14, 5, 260, 223)},
}
# the paper's post-hoc findings (section 6.3): (a, b, "a > b" significant at p < 0.05, or "n.s.")
PAPER_POSTHOC = [("r2", "r3", ">"), ("r2", "r4", ">"), ("r2", "r1", ">"), ("r3", "r1", ">"), ("r4", "r1", ">"),
                 ("r3", "r4", "n.s.")]
TABLE = {"env1": "Table 3", "env2": "Table 4"}


@dataclass(frozen=True)
class ObstaclesCfg:
    """``+experiment=table3`` (Tables 3 and 4, the ANOVA, CMA-ES, Figs. 6, 8, 9)."""

    runs: int = setting(30, lo=2, hi=100_000)  # learners per reward and environment
    seed: int = setting(0, lo=0, hi=2**31)
    environments: tuple[str, ...] = setting(("env1", "env2"), choices=("env1", "env2"))
    cmaes: bool = True  # CMA-ES from the R3 learners' starts

    def __post_init__(self) -> None:
        require(len(self.environments) > 0, "experiments.table3.environments: expected at least one of env1, env2")


@dataclass(frozen=True)
class Fig10Cfg:
    """``+experiment=fig10``."""

    trials: int = setting(16, lo=1, hi=100_000)
    seed: int = setting(0, lo=0, hi=2**31)


def reward_cfg(kind: str) -> RewardCfg:
    return RewardCfg(kind=kind, a=1.5, beta=0.25, p=2000)  # section 6.3


def tables(runs: int, seed: int = 0, environments: tuple[str, ...] = ("env1", "env2")) -> tuple[dict, dict]:
    """Every reward in each environment: ``runs`` independent learners (one per run, batched in
    one call; the same seed, hence the same starts and initial weights, for every reward)."""
    rows, results = {}, {}
    cells = [(env, kind) for env in environments for kind in REWARDS]
    for env, kind in progress(cells, desc="table3 rewards", unit="cell"):
        res = gt.solve(env, trials=runs, seed=seed, reward=reward_cfg(kind), solver=SolverCfg.paper())
        results[env, kind] = res
        trials = res.trials
        reached = [t.reinforcement > THRESHOLD for t in trials]  # the paper's success: r above the threshold
        success = [t for t, ok in zip(trials, reached, strict=True) if ok]
        r1 = [1 - math.tanh(1.5 * t.total_error_mm / 1000) for t in trials]
        positioning = sum(not ok and r <= THRESHOLD for ok, r in zip(reached, r1, strict=True))
        collision = sum(t.collisions > 0 for t in trials)
        iters = [t.iterations for t in success]
        rows[env, kind] = {"success": len(success), "positioning": positioning, "collision": collision,
                           "mean": float(np.mean(iters)) if iters else float("nan"),
                           "std": float(np.std(iters, ddof=1)) if len(iters) > 1 else float("nan"),
                           "free": sum(ok and t.collisions == 0 for t, ok in zip(trials, reached, strict=True)),
                           "iters": iters}
    return rows, results


def anova(rows: dict, environments: tuple[str, ...] = ("env1", "env2")) -> tuple[str, dict]:
    """One-way ANOVA of the successes' iteration counts across the rewards, environments pooled,
    and Bonferroni-corrected pairwise t-tests (6 pairs)."""
    from scipy import stats

    groups = {k: [i for env in environments for i in rows[env, k]["iters"]] for k in REWARDS}
    usable = all(len(v) >= 2 for v in groups.values())
    f, p = stats.f_oneway(*[groups[k] for k in REWARDS]) if usable else (float("nan"), float("nan"))
    n = sum(len(v) for v in groups.values())
    pairs, tests = [], {}
    for i, a in enumerate(REWARDS):
        for b in REWARDS[i + 1:]:
            t, pp = stats.ttest_ind(groups[a], groups[b]) if usable else (float("nan"), float("nan"))
            pb = min(1.0, 6 * pp)
            tests[a, b] = (float(t), float(pb))
            pairs.append([f"{a.upper()} vs {b.upper()}", np.mean(groups[a]) if groups[a] else float("nan"),
                          np.mean(groups[b]) if groups[b] else float("nan"), t, pb])
    text = (f"One-way ANOVA on the iterations of the successes, {' and '.join(environments)} pooled: "
            f"**F(3, {n - 4}) = {f:.2f}, p = {p:.2g}** (paper: F(3, 161) = 14.33, p < 0.0001).\n\n"
            + markdown_table(["comparison", "mean a", "mean b", "t", "p (Bonferroni, x6)"], pairs, floatfmt=".3g"))
    return text, {"F": float(f), "p": float(p), "df": n - 4, "tests": tests,
                  "means": {k: float(np.mean(v)) if v else float("nan") for k, v in groups.items()}}


def posthoc_rows(stats_: dict) -> tuple[list[list[str]], list[str]]:
    """The paper's post-hoc findings beside ours; and the ones that differ, one sentence each."""
    rows, differ = [], []
    for a, b, claim in PAPER_POSTHOC:
        key = (a, b) if (a, b) in stats_["tests"] else (b, a)
        _, p = stats_["tests"][key]
        ma, mb = stats_["means"][a], stats_["means"][b]
        ours = ">" if p < 0.05 and ma > mb else "<" if p < 0.05 else "n.s."
        paper = f"{a.upper()} {'>' if claim == '>' else 'vs'} {b.upper()}: {'p < 0.05' if claim == '>' else 'n.s.'}"
        rows.append([paper, f"{ma:.0f} vs {mb:.0f} iterations, p = {p:.2g} ({ours})", "yes" if ours == claim else "no"])
        if ours != claim:
            finds = f"more iterations with {a.upper()}" if claim == ">" else "no significant difference"
            differ.append(f"{a.upper()} vs {b.upper()}: the paper finds {finds}; "
                          f"we find {ma:.0f} vs {mb:.0f} iterations, Bonferroni p = {p:.2g}.")
    return rows, differ


def cmaes_rows(runs: int, results: dict, environments: tuple[str, ...] = ("env1", "env2")) -> dict:
    """CMA-ES from each R3 learner's start, with R3 and the proxy's collision count as the signal,
    the same budget (2000 evaluations); the reported posture's collisions by FCL."""
    import torch

    out = {}
    for env in progress(environments, desc="table3 CMA-ES", unit="env"):
        problem = gt.GraspProblem.from_task(env)
        robot, ik = robot_and_ik(problem.robot_cfg)
        solver = SolverCfg.paper()
        environment = build_environment(robot, problem, ik, solver, torch.float32, "cpu", reward_cfg("r3"))
        scene = CollisionScene(robot, problem)
        starts = results[env, "r3"].outcome.start
        stats_ = []
        t0 = time.perf_counter()
        cmaes = SolverCfg.paper(method="cmaes", max_iterations=2000, history=False)  # one CMA-ES per start
        o = run_cmaes(environment, runs, 0, cmaes, reward_cfg("r3"), start=starts[:runs])
        config, ev = environment.finish(o.config, o.evaluation)
        for k, fields in enumerate(environment.report(config, ev).fields):
            collisions = scene.count(trial_posture(robot, fields))
            ok = bool(o.success[k])
            stats_.append((ok, ok and collisions == 0, int(o.iterations[k]), fields["total_error_mm"]))
        evals = [s[2] for s in stats_ if s[0]]
        out[env] = {"success": sum(s[0] for s in stats_), "free": sum(s[1] for s in stats_),
                    "evals": float(np.mean(evals)) if evals else float("nan"), "seconds": time.perf_counter() - t0}
    return out


def table_markdown(env: str, rows: dict, cma: dict | None) -> str:
    """Table 3 (env1) or 4 (env2): ours (paper), and CMA-ES under R3."""
    header = ["", *[k.upper() for k in REWARDS]]
    body = []
    for label, key, idx in (("success", "success", 0), ("failure: positioning", "positioning", 1),
                            ("failure: collision", "collision", 2), ("mean iterations", "mean", 3),
                            ("std iterations", "std", 4)):
        body.append([label, *[f"{rows[env, k][key]:.0f} ({PAPER[env][k][idx]})" for k in REWARDS]])
    body.append(["**success + collision-free**", *[f"**{rows[env, k]['free']}**" for k in REWARDS]])
    if cma is not None:
        body.append(["CMA-ES, R3: success / + collision-free", "", "", f"{cma[env]['success']} / {cma[env]['free']}",
                     ""])
        body.append(["CMA-ES, R3: mean evaluations of successes", "", "", f"{cma[env]['evals']:.0f}", ""])
    return markdown_table(header, body)


def figures(out: Path, results: dict) -> list[Figure]:
    """Figs. 6, 8 and 9 (8 and 9 from env1's learners when env1 was run, else env2's)."""
    import torch

    plt = _plt()
    # Fig. 6: R3 and R4 with R1 = 0.99 against the iteration, R4 for c = 1..4 collisions
    i = np.linspace(0, 2000, 201)
    fig, ax = plt.subplots(1, 1, figsize=(6, 4), dpi=110)
    ax.plot(i, 0.99 / (1 + i / 2000), label="R3 (collision)", linewidth=2)
    for c in (2, 3, 4):
        ax.plot(i, 0.99 / (1 + c ** 0.25 * i / 2000), label=f"R4, c = {c}", linestyle="--")
    ax.axhline(0.99, color="k", linewidth=0.8, label="R1 = 0.99 (and R2 = R1 / 2 = 0.495 below)")
    ax.axhline(0.495, color="grey", linewidth=0.8)
    ax.set_xlabel("iteration i (p = 2000)")
    ax.set_ylabel("reinforcement")
    ax.set_title("Fig. 6: shaped reinforcements with R1 = 0.99", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "fig6_rewards.png")
    plt.close(fig)
    # Fig. 8 and 9: one learner under each reward (the successful R3 learner with the most collisions early on)
    env = "env1" if ("env1", "r3") in results else "env2"
    hist3 = results[env, "r3"].outcome.history
    k = int(torch.argmax(hist3["collisions"][:200].sum(0) * torch.as_tensor(
        [t.reinforcement > THRESHOLD for t in results[env, "r3"].trials])))
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), dpi=110, sharex=True)
    for ax, kind in zip(axes.ravel(), REWARDS, strict=True):
        h = results[env, kind].outcome.history
        stop = results[env, kind].trials[k].iterations  # the curves up to this learner's stop
        x = np.arange(1, stop + 1)
        ax.plot(x, h["reinforcement"][:stop, k], label="reinforcement", linewidth=0.7)
        ax.plot(x, h["expected"][:stop, k], label="expected reinforcement", linewidth=1.4)
        ax.plot(x, h["sigma"][:stop, k], label="sigma (mean)", linestyle="--", linewidth=1.4)
        ax.set_title(f"{kind.upper()} ({env}, learner {k}, stops at {stop})", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[1]:
        ax.set_xlabel("iteration")
    fig.suptitle("Fig. 8: learning parameters under R1-R4", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "fig8_learning.png")
    plt.close(fig)
    fig, ax = plt.subplots(1, 1, figsize=(6, 3.5), dpi=110)
    stop = results[env, "r3"].trials[k].iterations
    ax.plot(np.arange(1, stop + 1), hist3["collisions"][:stop, k])
    ax.set_xlabel("iteration")
    ax.set_ylabel("collisions (the loop's count)")
    ax.set_title(f"Fig. 9: collisions under R3 ({env}, learner {k})", fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "fig9_collisions.png")
    plt.close(fig)
    return [Figure("fig6_rewards.png", "Fig. 6: the reinforcements R3 and R4 (c = 2, 3, 4 collisions) against the "
                                       "iteration with R1 = 0.99; R1 and R2 for reference."),
            Figure("fig8_learning.png", f"Fig. 8: reinforcement, expected reinforcement and exploration (sigma) of one "
                                        f"{env} learner under a/ R1, b/ R2, c/ R3, d/ R4 (same start and weights)."),
            Figure("fig9_collisions.png", "Fig. 9: the number of collisions of the Fig. 8c learner (R3) against the "
                                          "iteration.")]


def run_tables(cfg: ObstaclesCfg, out: Path) -> ExperimentReport:
    """Tables 3 and 4, the ANOVA and post-hoc tests, CMA-ES and Figs. 6, 8, 9."""
    envs = tuple(cfg.environments)
    rows, results = tables(cfg.runs, cfg.seed, envs)
    anova_text, stats_ = anova(rows, envs)
    posthoc, differ = posthoc_rows(stats_)
    cma = cmaes_rows(cfg.runs, results, envs) if cfg.cmaes else None
    figs = figures(out, results)
    lines = [f"Tasks {', '.join(f'`{e}`' for e in envs)}; arm_hand's ACNN defaults (alpha_BP = alpha_SRV = 0.03, "
             "rho = 0.01, 20/20 hidden units, a random start within the task's bounds), a = 1.5, p = 2000, "
             f"beta = 0.25, budget 2000 iterations, success r > 0.99. {cfg.runs} runs per reward and environment, one "
             f"learner per run (batched, seed {cfg.seed}: every reward sees the same starts and initial weights). "
             "Cells are **ours (paper)**; the paper ran 30.", "",
             "Failures: *positioning* = the run ended with R1 <= 0.99 (total error >= 6.7 mm); *collision* = the "
             "reported posture collides (FCL), counted over all runs as the paper's R1 column implies (26 successes "
             "and 22 collision failures of 30). Ours adds *success + collision-free*.", ""]
    numbers, mismatches = {}, []
    scale = cfg.runs / 30
    for env in envs:
        lines += [f"### {TABLE[env]}: {env}", "", table_markdown(env, rows, cma), ""]
        for kind in REWARDS:
            r, p = rows[env, kind], PAPER[env][kind]
            for key in ("success", "positioning", "collision", "free", "mean"):
                numbers[f"{env}/{kind}/{key}"] = float(r[key])
            if abs(r["success"] - p[0] * scale) > 5 * scale:
                mismatches.append(f"{TABLE[env]}, {kind.upper()}: {r['success']}/{cfg.runs} successes against the "
                                  f"paper's {p[0]}/30.")
            if r["iters"] and not 0.5 <= r["mean"] / p[3] <= 2:
                mismatches.append(f"{TABLE[env]}, {kind.upper()}: successes take {r['mean']:.0f} iterations on "
                                  f"average against the paper's {p[3]}.")
        if cma is not None:
            numbers[f"{env}/cmaes/success"] = float(cma[env]["success"])
            numbers[f"{env}/cmaes/free"] = float(cma[env]["free"])
    best = {env: max(REWARDS, key=lambda k, e=env: rows[e, k]["free"]) for env in envs}
    lines += ["### ANOVA and Bonferroni post-hoc tests", "", anova_text, "",
              markdown_table(["the paper's finding", "ours", "agrees"], posthoc), "",
              "Collision-free successes, the reward the paper recommends (R3) beside the best of ours: "
              + "; ".join(f"{env}: R3 {rows[env, 'r3']['free']}, best {best[env].upper()} "
                          f"{rows[env, best[env]]['free']}" for env in envs) + ".", ""]
    numbers["anova F"], numbers["anova p"] = stats_["F"], stats_["p"]
    if not stats_["p"] < 0.0001:
        mismatches.append(f"ANOVA: F({3}, {stats_['df']}) = {stats_['F']:.2f}, p = {stats_['p']:.2g}; the paper has "
                          "F(3, 161) = 14.33, p < 0.0001.")
    mismatches += [f"Post-hoc: {d}" for d in differ]
    if cma is not None:
        lines += ["CMA-ES (sigma0 = 0.25 of the normalised space, restarts on convergence) from each R3 learner's "
                  "start, with the same R3 and the loop's collision count as a black box, 2000 evaluations "
                  "(one evaluation = one SRV iteration): " + "; ".join(
                      f"{env}: {cma[env]['success']}/{cfg.runs} successes, {cma[env]['free']} collision-free, "
                      f"{cma[env]['evals']:.0f} evaluations on average" for env in envs) + ".", ""]
    timings = {f"{env}/cmaes seconds": cma[env]["seconds"] for env in envs} if cma is not None else {}
    checks = []
    for env in envs:
        shaped, strict = min(rows[env, "r3"]["free"], rows[env, "r4"]["free"]), rows[env, "r2"]["free"]
        checks.append((f"{env}: shaping (R3, R4) at least as many collision-free successes as R2 ({shaped} vs "
                       f"{strict})", shaped >= strict))
        checks.append((f"{env}: R3 collision-free successes {rows[env, 'r3']['free']} >= 22 of 30 "
                       f"({22 * scale:.1f} of {cfg.runs})", rows[env, "r3"]["free"] >= 22 * scale))
    return ExperimentReport("table3", "Tables 3 and 4: the arm among unknown obstacles (section 6.3), "
                            "with the ANOVA and Figs. 6, 8, 9", "\n".join(lines), figures=figs,
                            tables=[TABLE[e] for e in envs], numbers=numbers, timings=timings, mismatches=mismatches,
                            checks=checks, results=results)


def run_fig10(cfg: Fig10Cfg, out: Path) -> ExperimentReport:
    """Fig. 10: the best of ``trials`` learners on task ``fig10`` (a cylinder among three obstacles)."""
    problem = gt.GraspProblem.from_task("fig10")
    res = gt.solve(problem, trials=cfg.trials, seed=cfg.seed, solver={"contact_model": "point"})  # the paper's
    robot, _ = robot_and_ik(problem.robot_cfg)
    render_robot(robot, posture_panels(robot, problem, res), out / "fig10_posture.png")
    free = sum(t.success and t.collisions == 0 for t in res.trials)
    body = (f"Task `fig10` (a cylinder among three obstacles), the arm's defaults (R3), {cfg.trials} learners "
            f"(seed {cfg.seed}): the best trial ends {res.best.total_error_mm:.3g} mm from the contacts with "
            f"{res.best.collisions} collision(s) (FCL); {free}/{cfg.trials} learners found a collision-free grasp.")
    mismatches = [] if res.best.collisions == 0 and res.best.total_error_mm < 1 else [
        f"Fig. 10: our best posture ends {res.best.total_error_mm:.2f} mm from the contacts with "
        f"{res.best.collisions} collision(s); the paper shows a collision-free grasp."]
    return ExperimentReport("fig10", "Fig. 10: the arm among three obstacles (section 6.3)", body,
                            figures=[Figure("fig10_posture.png", "Fig. 10: the upper-limb posture found to grasp a "
                                                                 "cylinder surrounded by 3 obstacles (two views).")],
                            tables=[], numbers={"best total mm": res.best.total_error_mm, "free": float(free)},
                            mismatches=mismatches)
