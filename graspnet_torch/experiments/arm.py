"""The arm and hand among obstacles as a product (beyond the paper's section 6.3): 16 learners
batched on env1 and env2, and random reachable arm problems among random obstacles.

``product``: ``trials`` (16) learners batched on one problem, R3 (the arm's default): the best trial
collision-free with total error < 1 mm, from ``runs`` seeds (1000, 1001, ...) per environment, and
the wall time of the whole ``gt.solve`` call. Two stop rules: every learner runs to its own stop
(the paper's protocol, the default) and ``solver.stop=8`` (the batch stops once 8 of the 16
learners succeeded: "give me a grasp").

``random``: ``random_problems`` problems of
:func:`~graspnet_torch.collision.problems.random_obstacle_problems` (seed 7), solved with R3 and ``trials``
(16) learners (seed k + 1 for problem k): solved when the best trial is collision-free with total
error < 10 mm.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision.problems import random_obstacle_problems
from graspnet_torch.experiments.report import ExperimentReport, progress
from graspnet_torch.settings import setting
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.table import markdown_table

__all__ = ["ArmCfg", "product", "random_arm", "run_arm"]

ENVIRONMENTS = ("env1", "env2")
STOPS = (None, 8)


@dataclass(frozen=True)
class ArmCfg:
    """``+experiment=arm``."""

    runs: int = setting(30, lo=1, hi=100_000)  # seeds per environment and stop rule
    trials: int = setting(16, lo=1, hi=10_000)  # learners batched per solve (the product and the random problems)
    random_problems: int = setting(30, lo=0, hi=100_000)  # random reachable arm problems


def product(n: int, trials: int = 16) -> dict:
    """(environment, stop) -> grasps found ``ok`` of ``n`` (``trials`` learners each) and the median
    and max wall time (s)."""
    out = {}
    cells = [(env, enough) for env in ENVIRONMENTS for enough in STOPS]
    for env, enough in progress(cells, desc="arm: the product", unit="cell"):
        ok, walls = 0, []
        for s in range(n):
            t0 = time.perf_counter()
            res = gt.solve(env, trials=trials, seed=1000 + s, solver=SolverCfg.paper(stop=enough))
            walls.append(time.perf_counter() - t0)
            ok += res.best.collisions == 0 and res.best.total_error_mm < 1.0
        out[env, enough] = {"ok": ok, "median_s": float(np.median(walls)), "max_s": float(np.max(walls))}
    return out


def random_arm(n: int, trials: int = 16) -> dict:
    """``n`` random reachable arm problems among obstacles, solved (see the module's docstring)."""
    problems = random_obstacle_problems(gt.load_robot("arm_hand"), n, seed=7)
    solved = 0
    for k, problem in enumerate(progress(problems, desc="arm: random problems", unit="problem")):
        res = gt.solve(problem, trials=trials, seed=k + 1)
        solved += res.best.collisions == 0 and res.best.total_error_mm < 10.0
    return {"solved": solved, "n": n}


def _stop_name(enough: int | None) -> str:
    return "every trial to its own stop (the paper)" if enough is None else f"solver.stop={enough}"


def run_arm(cfg: ArmCfg, out: Path) -> ExperimentReport:
    """The product and the random arm problems, with this project's targets as checks."""
    import torch

    prod = product(cfg.runs, cfg.trials)
    rand = random_arm(cfg.random_problems, cfg.trials)
    checks = []
    for env in ENVIRONMENTS:
        fast = prod[env, 8]  # the product setting; the default protocol's times are reported beside it
        checks.append((f"{env}, solver.stop=8: the product {fast['ok']}/{cfg.runs} >= 29/30, median "
                       f"{fast['median_s']:.2f} s < 2 s", fast["ok"] >= 29 * cfg.runs / 30 and fast["median_s"] < 2))
    checks.append((f"random reachable arm problems {rand['solved']}/{rand['n']} >= 90 %",
                   rand["solved"] >= 0.9 * rand["n"]))
    doc = __doc__.split("\n\n")
    body = [f"### The product: {cfg.trials} learners batched, R3", "", " ".join(doc[1].split()), "",
            f"Here: {cfg.trials} learners, {cfg.runs} seeds per environment, {torch.get_num_threads()} torch "
            "thread(s).", "",
            markdown_table(["environment", "stop rule", "grasps found", "median wall time (s)", "max (s)"],
                           [[env, _stop_name(e), f"{prod[env, e]['ok']}/{cfg.runs}", prod[env, e]["median_s"],
                             prod[env, e]["max_s"]] for env in ENVIRONMENTS for e in STOPS], floatfmt=".2f"), "",
            "### Random reachable arm problems", "", " ".join(doc[2].split()), "",
            " ".join((random_obstacle_problems.__doc__ or "").split()), "",
            f"**{rand['solved']}/{rand['n']}** solved.", ""]
    numbers = {f"product/{env}/{'own stop' if e is None else f'stop={e}'}/found": float(prod[env, e]["ok"])
               for env in ENVIRONMENTS for e in STOPS}
    numbers.update({"random/solved": float(rand["solved"]), "random/problems": float(rand["n"])})
    timings = {f"product/{env}/{'own stop' if e is None else f'stop={e}'}/median s": prod[env, e]["median_s"]
               for env in ENVIRONMENTS for e in STOPS}
    return ExperimentReport("arm", "The arm among obstacles as a product: 16 learners batched, random problems",
                            "\n".join(body), tables=["The product"], numbers=numbers, timings=timings, checks=checks,
                            results={"product": prod, "random": rand})

