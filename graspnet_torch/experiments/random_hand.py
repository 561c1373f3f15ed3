"""Random reachable problems for the paper's hand: does the HCNN solve them (beyond the paper)?

Each problem (:func:`~graspnet_torch.tasks.random.random_hand_problem`, seed k for problem k): a
palm pose uniform within the hand's bounds (paper Table 1), finger joints uniform within limits, 2
to 5 fingers chosen at random; their fingertips are the contacts, so a solution exists; the palm is
searched in the same box (``palm_bounds: robot``), as in the paper. Solved with the paper's
protocol (``solver=paper``: ``trials`` trials, 2000 iterations, each stops at r > 0.99, fingers
refined, seed 0); a problem counts as solved when the result's total error is under 10 mm. The
experiment ``solvers`` compares every solver, the default included, on such problems.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.experiments.report import ExperimentReport, progress
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import setting
from graspnet_torch.solver import SolverCfg
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.tasks.random import random_hand_problem

__all__ = ["SOLVED_PCT", "RandomHandCfg", "in_robot_box", "run_random_hand"]

SOLVED_PCT = 95.0


@dataclass(frozen=True)
class RandomHandCfg:
    """``+experiment=random_hand``."""

    problems: int = setting(100, lo=1, hi=100_000)
    trials: int = setting(20, lo=1, hi=10_000)


def in_robot_box(problem: GraspProblem, robot: Robot) -> GraspProblem:
    """``problem`` with its palm searched in the robot config's box (``palm_bounds: robot``)."""
    return GraspProblem.from_mapping({**problem.to_mapping(), "palm_bounds": "robot"}, robot_cfg=robot.cfg,
                                        source=problem.source)


def run_random_hand(cfg: RandomHandCfg, out: Path) -> ExperimentReport:
    """Solve the problems; the share solved, by the number of contact fingers."""
    robot = gt.load_robot("hand")
    errors, fingers, seconds = [], [], []
    for seed in progress(range(cfg.problems), total=cfg.problems, desc="random hand problems", unit="problem"):
        problem = in_robot_box(random_hand_problem(robot, seed), robot)
        t0 = time.perf_counter()
        result = gt.solve(problem, trials=cfg.trials, seed=0, solver=SolverCfg.paper())
        seconds.append(time.perf_counter() - t0)
        errors.append(result.total_error_mm)
        fingers.append(len(problem.fingers))
    e, nf = np.array(errors), np.array(fingers)
    solved = float(np.mean(e < 10) * 100)
    rows = [[k, int((nf == k).sum()), f"{np.mean(e[nf == k] < 10) * 100:.1f} %", f"{np.median(e[nf == k]):.3f}"]
            for k in sorted(set(nf.tolist()))]
    body = [" ".join(__doc__.split("\n\n")[1].split()), "",
            f"Here: {cfg.problems} problems, {cfg.trials} trials each.", "",
            f"**Solved to total error < 10 mm: {solved:.1f} %** (target: at least {SOLVED_PCT:g} %); "
            f"< 1 mm: {np.mean(e < 1) * 100:.1f} %; median {np.median(e):.3f} mm; mean solve time "
            f"{np.mean(seconds):.2f} s.", "",
            markdown_table(["fingers", "problems", "solved < 10 mm", "median error mm"], rows), ""]
    numbers = {"solved < 10 mm %": solved, "solved < 1 mm %": float(np.mean(e < 1) * 100),
               "median error mm": float(np.median(e))}
    return ExperimentReport("random_hand", "The HCNN on random reachable hand problems", "\n".join(body),
                            numbers=numbers, timings={"mean solve s": float(np.mean(seconds))},
                            checks=[(f"solver=paper: {solved:.1f} % solved to < 10 mm >= {SOLVED_PCT:g} %",
                                     solved >= SOLVED_PCT)])
