"""Solve a grasp from the command line: the main job.

Resolves the problem (a file or a shipped task), validates everything before any work, runs
``gt.solve``, prints a per-trial table and a summary, writes the result JSON (atomically),
TensorBoard curves, a picture of the best posture with the object and contacts, and the learning
curves (like the paper's Fig. 3).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspnet_torch.errors import ProblemError
from graspnet_torch.solver.api import robot_and_ik, solve
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.srv.network import SRVNetCfg
from graspnet_torch.table import format_table
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["log_tensorboard", "posture_of", "resolve_problem", "solve_grasp"]


def resolve_problem(problem: str | None, task: Mapping[str, Any] | str | None, robot: str | None) -> GraspProblem:
    """The problem file if given, else the task (a task name, or a task config as composed by
    Hydra from ``configs/task/``); checks that an explicit robot agrees."""
    if problem:
        result = GraspProblem.from_file(problem)
    elif isinstance(task, str):
        result = GraspProblem.from_task(task)
    elif isinstance(task, Mapping):
        name = task.get("name", "task")
        result = GraspProblem.from_mapping(task, source=f"configs/task/{name}.yaml")
    else:
        raise ProblemError("nothing to solve: give problem=PATH or task=NAME")
    if robot and robot != result.robot:
        raise ProblemError(f"{result.source}: the problem is for robot '{result.robot}', but robot={robot} was given")
    return result


def _positive_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ProblemError(f"{name} must be a positive integer, got {value!r}")
    return value


def _out_path(out: str | None, run_dir: Path) -> Path:
    path = Path(out) if out else run_dir / "result.json"
    if path.is_dir():
        raise ProblemError(f"out={path} is a directory; give a file path for the result JSON")
    return path


def posture_of(robot, trial: TrialResult):
    """The :class:`~graspnet_torch.robot.Posture` of a reported trial (degrees -> radians)."""
    from graspnet_torch.robot.robot import Posture

    d = math.pi / 180
    pose = torch.tensor(trial.palm_pose[:3] + [a * d for a in trial.palm_pose[3:]], dtype=torch.float64)
    q = torch.tensor([[a * d for a in trial.joints[f]] for f in robot.finger_names], dtype=torch.float64)
    return Posture(palm_pose=pose, fingers=q, body=torch.zeros(0, dtype=torch.float64))


def log_tensorboard(log_dir: Path, result: GraspResult, fingers: tuple[str, ...], every: int = 10) -> None:
    """Per trial: reinforcement, expected reinforcement, mean sigma, total and per-finger error."""
    history = result.outcome.history if result.outcome is not None else None
    if history is None:
        return
    from torch.utils.tensorboard import SummaryWriter

    with SummaryWriter(str(log_dir)) as writer:
        K, T = history["total"].shape
        for k in list(range(0, K, every)) + ([K - 1] if (K - 1) % every else []):
            for t in range(T):
                tag = f"trial_{t:02d}"
                writer.add_scalar(f"{tag}/reinforcement", float(history["reinforcement"][k, t]), k + 1)
                writer.add_scalar(f"{tag}/expected_reinforcement", float(history["expected"][k, t]), k + 1)
                writer.add_scalar(f"{tag}/sigma_mean", float(history["sigma"][k, t]), k + 1)
                writer.add_scalar(f"{tag}/total_error_mm", float(history["total"][k, t]) * 1000, k + 1)
                for f, finger in enumerate(fingers):
                    writer.add_scalar(f"{tag}/error_mm/{finger}", float(history["errors"][k, t, f]) * 1000, k + 1)


def _trial_table(result: GraspResult, fingers: tuple[str, ...]) -> str:
    headers = ["trial", "success", "iterations", "total mm", *[f"{f} mm" for f in fingers], "reinforcement"]
    rows = [[k, "yes" if t.success else "no", t.iterations, t.total_error_mm,
             *[t.fingertip_error_mm[f] for f in fingers], round(t.reinforcement, 5)]
            for k, t in enumerate(result.trials)]
    return format_table(headers, rows, floatfmt=".3g")


def solve_grasp(cfg: Mapping[str, Any], run_dir: str | Path) -> GraspResult:
    """The job behind ``scripts/solve_grasp.py``; ``cfg`` is the composed Hydra config as a dict."""
    run_dir = Path(run_dir)
    robot_cfg = cfg.get("robot")
    robot_name = robot_cfg.get("name") if isinstance(robot_cfg, Mapping) else robot_cfg
    problem = resolve_problem(cfg.get("problem"), cfg.get("task"), robot_name)
    trials = _positive_int(cfg.get("trials", 20), "trials")
    seed = cfg.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ProblemError(f"seed must be an integer, got {seed!r}")
    max_iterations = cfg.get("max_iterations")
    if max_iterations is not None:
        max_iterations = _positive_int(max_iterations, "max_iterations")
    out = _out_path(cfg.get("out"), run_dir)
    try:
        solver = SolverCfg(**{**dict(cfg.get("solver") or {}),
                              **({"max_iterations": max_iterations} if max_iterations else {})})
        srv = SRVNetCfg.from_mapping(dict(cfg.get("srv") or {}))
        reward = RewardCfg(**dict(cfg.get("reward") or {}))
        noise = NoiseCfg(**dict(cfg.get("noise") or {}))
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"invalid settings: {exc}") from None
    if not math.isfinite(noise.sigma) or noise.sigma < 0:
        raise ProblemError(f"noise.sigma must be a finite number >= 0, got {noise.sigma}")
    robot, ik = robot_and_ik(problem.robot)
    result = solve(problem, trials=trials, seed=seed, solver=solver, srv=srv, reward=reward, noise=noise,
                   robot=robot, finger_ik=ik, device=cfg.get("device", "cpu"))
    fingers = problem.fingers
    best = result.best
    print(_trial_table(result, fingers))
    n_ok = sum(t.success for t in result.trials)
    errors = np.array([t.total_error_mm for t in result.trials])
    per_finger = ", ".join(f"{f} {best.fingertip_error_mm[f]:.3f}" for f in fingers)
    if solver.stop_threshold is not None:
        stops = f"{n_ok}/{trials} trials reached r > {solver.stop_threshold:g}"
    else:  # noise presets: a noisy signal crosses any threshold by chance
        stops = f"no stopping threshold: {trials} trials ran their whole budget"
    print(f"\n{problem.name or problem.source}: {stops}; best total "
          f"error {best.total_error_mm:.3f} mm ({per_finger}); median {np.median(errors):.3f} mm; "
          f"{result.outcome.wall_time_s:.2f} s for {trials} trials batched")
    result.save(out)
    print(f"result: {out}")
    if cfg.get("tensorboard", True):
        log_tensorboard(run_dir / "tb", result, fingers, every=int(cfg.get("log_every", 10)))
    if cfg.get("pictures", True):
        _pictures(robot, problem, result, run_dir)
    return result


def _pictures(robot, problem: GraspProblem, result: GraspResult, run_dir: Path) -> None:
    from graspnet_torch.viz import Panel, plot_learning_curves, render_robot

    posture = posture_of(robot, result.best)
    meshes = tuple(s.trimesh() for s in ((problem.object,) if problem.object else ()) + problem.obstacles)
    contacts = problem.contacts_world()
    caption = f"{problem.name or 'problem'}: best trial, total error {result.best.total_error_mm:.2f} mm"
    panels = [Panel(caption, posture, (12.0, -150.0), contacts, meshes),
              Panel("side view", posture, (12.0, -60.0), contacts, meshes)]
    path = render_robot(robot, panels, run_dir / "posture.png")
    print(f"pictures: {path}", end="")
    history = result.outcome.history if result.outcome is not None else None
    if history is not None:
        best_index = result.trials.index(result.best)
        curves = plot_learning_curves({k: v.numpy() for k, v in history.items() if k != "errors"},
                                      run_dir / "learning.png", f"{problem.name or 'problem'}: learning of "
                                      f"{len(result.trials)} trials", highlight=best_index)
        print(f", {curves}", end="")
    print()
