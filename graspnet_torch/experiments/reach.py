"""Reach motions (beyond the paper: its section 8's future work): every grasp of the arm's
environments and of the MANUS protocol, reached from the robot's home posture.

1. env1, env2, fig10 (the arm among obstacles, R3): the grasps of ``arm_seeds`` solves each
   (16 trials, seeds 0, 1, ...);
2. the MANUS protocol's ``manus_positions`` cube positions (``gt.solve_many``, 8 learners each);
3. ``random_problems`` random reachable arm problems with 2-3 obstacles
   (:func:`~graspnet_torch.collision.problems.random_obstacle_problems`, seed 7, the obstacles also
   clear of the home posture the motion starts from).

Each successful grasp gets :func:`~graspnet_torch.motion.plan_reach` (OMPL RRT-Connect, then its
simplification; ``reach.timeout_s``) and every motion found is re-checked independently
(:func:`~graspnet_torch.motion.check_motion`: FCL at 0.5 degree / 1 mm along the lines between
its rows, its ends, the joint limits, the velocities and accelerations). Planning times are one
thread's wall times.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision.problems import random_obstacle_problems
from graspnet_torch.experiments.report import ExperimentReport, Figure, progress
from graspnet_torch.motion import check_motion
from graspnet_torch.settings import setting
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.manus import cube_problem, protocol_positions
from graspnet_torch.viz.motion import write_motion_frames

__all__ = ["ReachExperimentCfg", "run_reach"]

TARGETS = {"found_pct": 99.0, "median_s": 1.0, "p95_s": 5.0, "random_pct": 95.0}


@dataclass(frozen=True)
class ReachExperimentCfg:
    """``+experiment=reach``."""

    arm_seeds: int = setting(10, lo=1, hi=1000)  # grasps per arm environment (env1, env2, fig10)
    manus_positions: int = setting(64, lo=1, hi=64)  # of the protocol's 64 cube positions
    random_problems: int = setting(20, lo=1, hi=1000)  # random arm problems with 2-3 obstacles
    timeout_s: float = setting(5.0, lo=0.0, lo_open=True, hi=600.0)  # reach.timeout_s
    contact_model: str = setting("auto", choices=("point", "auto"))  # auto (default): surface where there is an object


@dataclass
class _Row:
    group: str
    solved: int = 0
    found: int = 0
    checked: int = 0
    reasons: dict | None = None

    def __post_init__(self) -> None:
        self.times: list[float] = []
        self.durations: list[float] = []
        self.reasons = {}


def _reach(row: _Row, problem: gt.GraspProblem, result: gt.GraspResult, cfg: gt.ReachCfg, robot: gt.Robot) -> None:
    if not result.success:
        return
    row.solved += 1
    motion = gt.plan_reach(problem, result, cfg, robot)
    row.times.append(motion.planning_time_s)
    if not motion.found:
        row.reasons[motion.reason] = row.reasons.get(motion.reason, 0) + 1
        return
    row.found += 1
    row.durations.append(float(motion.times[-1]))
    bad = check_motion(robot, problem, result.best, motion, cfg)
    row.checked += not bad
    for reason in bad:
        row.reasons[f"re-check: {reason}"] = row.reasons.get(f"re-check: {reason}", 0) + 1


def run_reach(cfg: ReachExperimentCfg, out: Path) -> ExperimentReport:
    reach = gt.ReachCfg(enabled=True, timeout_s=cfg.timeout_s)
    solver = {"contact_model": cfg.contact_model}
    arm, manus = gt.load_robot("arm_hand"), gt.load_robot("manus")
    rows: list[_Row] = []
    for task in progress(("env1", "env2", "fig10"), desc="reach: arm environments", unit="task"):
        row = _Row(task)
        problem = gt.GraspProblem.from_task(task)
        for seed in range(cfg.arm_seeds):
            _reach(row, problem, gt.solve(problem, trials=16, seed=seed, solver=solver), reach, arm)
        rows.append(row)
    row = _Row("MANUS protocol")
    positions = protocol_positions()[:: max(1, 64 // cfg.manus_positions)][: cfg.manus_positions]
    problems = [cube_problem(x, y) for x, y in positions]
    for problem, result in zip(problems, gt.solve_many(problems, trials=8, seed=0, solver=solver), strict=True):
        _reach(row, problem, result, reach, manus)
    rows.append(row)
    row = _Row("random arm problems, 2-3 obstacles")
    randoms = random_obstacle_problems(arm, cfg.random_problems, 7, clear_of=[arm.home_posture()])
    for k, problem in enumerate(progress(randoms, desc="reach: random arm problems", unit="problem")):
        _reach(row, problem, gt.solve(problem, trials=16, seed=k + 1, solver=solver), reach, arm)
    rows.append(row)
    table = []
    for r in rows:
        t = np.asarray(r.times) if r.times else np.zeros(1)
        reasons = "; ".join(f"{n} x {why}" for why, n in sorted(r.reasons.items(), key=lambda kv: -kv[1])) or "-"
        table.append([r.group, r.solved, f"{r.found} ({100 * r.found / max(1, r.solved):.0f} %)", r.checked,
                      f"{np.median(t):.2f}", f"{np.percentile(t, 95):.2f}",
                      f"{np.median(r.durations):.1f}" if r.durations else "-", reasons])
    arm_rows = rows[:4]
    solved = sum(r.solved for r in arm_rows)
    found = sum(r.found for r in arm_rows)
    times = np.asarray([t for r in arm_rows for t in r.times]) if solved else np.zeros(1)
    random_row = rows[4]
    figures = []
    first = next((r for r in rows if r.found), None)
    if first is not None:
        figures = _figure(out, reach, arm, solver)
    body = "\n\n".join([
        " ".join(__doc__.split("\n\n")[0].split()),
        f"Here: {cfg.arm_seeds} grasps per arm environment, {len(problems)} MANUS positions, "
        f"{cfg.random_problems} random arm problems; solver.contact_model = {cfg.contact_model} (auto: the surface "
        f"model's pads where the problem has an object, the pre-grasp backed off along the normals); "
        f"reach.timeout_s = {cfg.timeout_s:g} s, the check's step "
        f"{reach.resolution_deg:g} degree / {reach.resolution_mm:g} mm.",
        markdown_table(["grasps", "solved", "motion found", "re-checked clean", "planning s (median)",
                        "planning s (p95)", "motion s (median)", "why not (count)"], table), ""])
    pct = 100 * found / max(1, solved)
    random_pct = 100 * random_row.found / max(1, random_row.solved)
    checks = [
        (f"env1, env2, fig10, MANUS: {found}/{solved} grasps get a motion ({pct:.1f} %) >= {TARGETS['found_pct']:g} %",
         pct >= TARGETS["found_pct"]),
        (f"planning time median {np.median(times):.2f} s <= {TARGETS['median_s']:g} s",
         float(np.median(times)) <= TARGETS["median_s"]),
        (f"planning time p95 {np.percentile(times, 95):.2f} s <= {TARGETS['p95_s']:g} s",
         float(np.percentile(times, 95)) <= TARGETS["p95_s"]),
        (f"every motion re-checked clean: {sum(r.checked for r in rows)}/{sum(r.found for r in rows)}",
         all(r.checked == r.found for r in rows)),
        (f"random arm problems: {random_row.found}/{random_row.solved} solved ones get a motion ({random_pct:.1f} %) "
         f">= {TARGETS['random_pct']:g} %", random_pct >= TARGETS["random_pct"])]
    numbers = {f"{r.group}/found": r.found for r in rows}
    numbers.update({f"{r.group}/solved": r.solved for r in rows})
    return ExperimentReport("reach", "Reach motions: from the home posture to the grasp", body, numbers=numbers,
                            checks=checks, figures=figures,
                            timings={"planning s (median)": float(np.median(times)),
                                     "planning s (p95)": float(np.percentile(times, 95))})


def _figure(out: Path, reach: gt.ReachCfg, arm: gt.Robot, solver: dict) -> list[Figure]:
    """A few frames of env2's motion (the grasp of seed 0)."""
    problem = gt.GraspProblem.from_task("env2")
    result = gt.solve(problem, trials=16, seed=0, solver=solver)
    motion = gt.plan_reach(problem, replace(result), reach, arm)
    if not motion.found:
        return []
    write_motion_frames(arm, problem, motion, out / "reach_env2.png", frames=4)
    return [Figure("reach_env2.png", "The reach motion to env2's grasp from the home posture: four moments "
                                     "(the planned approach, fingers open, then the fingers closing).")]
