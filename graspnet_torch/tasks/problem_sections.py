"""Sections of a problem file checked on their own for :meth:`GraspProblem.from_mapping
<graspnet_torch.tasks.problem.GraspProblem.from_mapping>`: the robot it names, a free hand's palm
bounds and an arm's joint bounds. Every refusal is a :class:`~graspnet_torch.errors.ProblemError`
that names the file and the entry."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

import numpy as np

from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.robot.config import PoseBounds, RobotCfg, available_robots, load_robot_cfg
from graspnet_torch.robot.shape import unknown_keys
from graspnet_torch.settings import MAX_ANGLE_DEG, clip, number_list

__all__ = ["joint_bounds_of", "palm_bounds_of", "robot_of"]


def robot_of(data: Mapping, source: str, robot_cfg: RobotCfg | None, folder: Path | None) -> tuple[str, RobotCfg]:
    """The problem's robot: its name and config (``robot_cfg`` when given and the problem names
    it; else loaded from ``configs/robot/`` or a robot YAML path, looked up beside the problem first)."""
    robot = data.get("robot")
    if not isinstance(robot, str) or not robot or len(robot) > 4096:
        raise ProblemError(f"{source}: 'robot' must name a robot ({', '.join(available_robots())})")
    by_path = robot.endswith((".yaml", ".yml")) or "/" in robot or os.sep in robot
    if by_path and folder is not None and not Path(robot).is_absolute() and (Path(folder) / robot).is_file():
        robot = str(Path(folder) / robot)  # a robot config beside the problem
    if robot_cfg is None or by_path:
        try:
            loaded = load_robot_cfg(robot)
        except ConfigError as exc:
            raise ProblemError(f"{source}: robot: {exc}") from None
        if robot_cfg is not None and loaded.name != robot_cfg.name:
            raise ProblemError(f"{source}: the problem is for robot '{loaded.name}' ({clip(robot, 200)}), "
                               f"but robot={robot_cfg.name} was given")
        robot_cfg = robot_cfg or loaded
        robot = robot_cfg.name
    elif robot_cfg.name != robot:
        raise ProblemError(f"{source}: the problem is for robot '{robot}', but robot={robot_cfg.name} was given")
    return robot, robot_cfg


def palm_bounds_of(data: Mapping, source: str, robot: str, robot_cfg: RobotCfg
                   ) -> PoseBounds | Literal["robot"] | None:
    """The problem's ``palm_bounds``: a box (m, degrees in the file), ``"robot"`` (the robot
    config's box, which must exist), or None (left out: the search follows the contacts)."""
    if data.get("palm_bounds") == "robot":
        if robot_cfg.palm_bounds is None:
            raise ProblemError(f"{source}: palm_bounds: robot '{robot}' has no palm_bounds in its config "
                               f"(give {{min: [...], max: [...]}}, or leave palm_bounds out: the search "
                               f"follows the contacts)")
        return "robot"
    if data.get("palm_bounds") is not None:
        try:
            return PoseBounds.from_degrees(data["palm_bounds"], f"{source}: palm_bounds")
        except ConfigError as exc:
            raise ProblemError(str(exc)) from None
    return None


def joint_bounds_of(data: Mapping, source: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The problem's arm ``bounds``: (min, max) (j,) each, in chain order as written (degrees for
    revolute joints, metres for prismatic ones), or None (the joint limits)."""
    if data.get("bounds") is None:
        return None
    raw_b = data["bounds"]
    if not isinstance(raw_b, Mapping) or unknown_keys(raw_b, {"min", "max"}) or len(raw_b) != 2:
        raise ProblemError(f"{source}: bounds: expected {{min: [...], max: [...]}} (arm joints in chain "
                           f"order, degrees or metres)")
    lo_b, hi_b = (np.asarray(number_list(raw_b[k], None, f"{source}: bounds.{k}", ProblemError,
                                         -MAX_ANGLE_DEG, MAX_ANGLE_DEG, "joint values"), dtype=np.float64)
                  for k in ("min", "max"))
    if lo_b.shape != hi_b.shape or not lo_b.size:
        raise ProblemError(f"{source}: bounds: min and max must list the same joints")
    if np.any(lo_b > hi_b):
        raise ProblemError(f"{source}: bounds: min > max for joint(s) "
                           f"{', '.join(str(i) for i in np.nonzero(lo_b > hi_b)[0])}")
    return (lo_b, hi_b)
