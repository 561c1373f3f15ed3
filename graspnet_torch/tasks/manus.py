"""The MANUS protocol's problems (paper section 7.2): the cube of task ``cube`` at 64 positions.

An 8 x 8 grid over 0.6 m x 1 m in front of the platform (x 0.6-1.2 m, y -0.5-0.5 m); at each, the
7 cm cube stands on a table (0.6 x 1.2 x 0.72 m) whose near edge is 0.1 m in front of it.
"""

from __future__ import annotations

import math

import numpy as np

from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["GRID_X", "GRID_Y", "cube_problem", "protocol_positions", "random_approach"]

GRID_X = np.linspace(0.6, 1.2, 8)  # m
GRID_Y = np.linspace(-0.5, 0.5, 8)


def cube_problem(x: float, y: float, approach: dict | None = None) -> GraspProblem:
    """The cube of task ``cube`` at (x, y) on a table whose near edge is 0.1 m in front of it;
    ``approach``: body joints (m / degrees) the search stays near."""
    data = {"name": f"cube@({x:.3f},{y:.3f})", "robot": "manus",
            "object": {"shape": "box", "size": [0.07, 0.07, 0.07], "pose": [x, y, 0.755, 0, 0, 0]},
            "points": [[0.0, 0.035, 0.0], [0.0, -0.035, 0.0]],
            "obstacles": [{"shape": "box", "size": [0.6, 1.2, 0.72], "pose": [x + 0.2, y, 0.36, 0, 0, 0]}]}
    if approach is not None:
        data["approach"] = approach
    return GraspProblem.from_mapping(data, f"<protocol {x:.3f},{y:.3f}>")


def protocol_positions() -> list[tuple[float, float]]:
    """The 64 cube positions (x, y), row by row."""
    return [(float(x), float(y)) for x in GRID_X for y in GRID_Y]


def random_approach(robot: Robot, joints: dict[str, float], rng: np.random.Generator, metres: float = 0.15,
                    degrees: float = 20.0) -> dict[str, float]:
    """An ``approach`` (body joints by name, m / degrees) near the configuration ``joints`` (same
    units): every revolute joint moved uniformly by up to ``degrees``, every prismatic one by up
    to ``metres`` / sqrt(2) (the base's x and y together within ``metres``), clipped to the limits."""
    approach = {}
    lower, upper = robot.body_limits
    for j, (name, kind) in enumerate(zip(robot.body_joint_names, robot.body.joint_types, strict=True)):
        step = rng.uniform(-degrees, degrees) if kind == "revolute" else rng.uniform(-metres, metres) / math.sqrt(2)
        scale = 180 / math.pi if kind == "revolute" else 1.0
        lo, hi = lower[j] * scale, upper[j] * scale
        approach[name] = float(np.clip(joints[name] + step, lo, hi))
    return approach
