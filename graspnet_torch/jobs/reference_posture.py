"""Is a problem reachable? Fit a reference posture and print it (problem-file format)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from graspnet_torch.jobs.configs import ReferencePostureJobCfg
from graspnet_torch.jobs.solve_grasp import resolve_problem
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import build
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.solver.reference_fit import ReferenceFit, find_reference_posture
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["prepare_reference", "reference_posture"]


def prepare_reference(cfg: Mapping[str, Any] | ReferencePostureJobCfg,
                      run_dir: str | None = None) -> tuple[ReferencePostureJobCfg, GraspProblem]:
    """The checks of the job (settings, problem) before any work."""
    job = build(ReferencePostureJobCfg, cfg)
    problem = resolve_problem(job.problem, job.task, None, job.allow_outside_paths)
    HandEnvironment.check(Robot(problem.robot_cfg), problem, SolverCfg())  # a free hand, its contacts in reach
    return job, problem


def reference_posture(cfg: Mapping[str, Any] | ReferencePostureJobCfg) -> ReferenceFit:
    job, problem = prepare_reference(cfg)
    robot = Robot(problem.robot_cfg)
    fit = find_reference_posture(robot, problem, restarts=job.restarts, seed=job.seed)
    pose = [round(float(v), 5) for v in fit.palm_pose[:3]] + [round(math.degrees(v), 3) for v in fit.palm_pose[3:]]
    print(f"{problem.name or problem.source}: total error {fit.total * 1000:.4f} mm "
          f"({', '.join(f'{f} {e * 1000:.4f}' for f, e in fit.errors.items())})")
    print("reference:")
    print(f"  palm_pose: {pose}")
    print("  joints:")
    for f, q in fit.joints.items():
        print(f"    {f}: {[round(math.degrees(v), 3) for v in q]}")
    return fit
