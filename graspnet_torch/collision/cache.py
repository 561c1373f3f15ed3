"""Collision models prepared once per distinct geometry: a problem's object, obstacles and contact
fingers (what the models depend on) as a content key, the built models kept in small LRU caches.

A program that solves many problems of the same scene (``gt.Solver``, tracking a sequence, or
``gt.solve`` called in a loop) builds the torch proxy and the FCL scene of that scene once. A
mesh is keyed by its path and its file's size and modification time, so an edited mesh is read
again.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np
import torch

from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.collision.scene import OBJECT_TOLERANCE_M, CollisionScene
from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["CACHE_SIZE", "geometry_key", "proxy_for", "scene_for"]

CACHE_SIZE = 16  # distinct scenes kept per kind of model
T = TypeVar("T")
_PROXIES: OrderedDict[tuple, CollisionProxy] = OrderedDict()
_SCENES: OrderedDict[tuple, CollisionScene] = OrderedDict()


def geometry_key(problem: GraspProblem) -> tuple:
    """What a problem's collision models depend on: its contact fingers (whose distal links may
    touch the object), its object and obstacles (kind, size, exact pose bytes; a mesh's path, scale
    and its file's size and modification time)."""
    parts: list = [problem.fingers]
    for shape in ([problem.object] if problem.object is not None else []) + list(problem.obstacles):
        stamp = None
        if shape.mesh is not None and Path(shape.mesh).is_file():
            stat = Path(shape.mesh).stat()
            stamp = (stat.st_size, stat.st_mtime_ns)
        parts.append((shape.kind, tuple(shape.size), np.asarray(shape.pose, dtype=np.float64).tobytes(),
                      str(shape.mesh), shape.scale, stamp))
    return tuple(parts)


def _cached(cache: OrderedDict[tuple, T], key: tuple, build: Callable[[], T]) -> T:
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = build()
    cache[key] = value
    while len(cache) > CACHE_SIZE:
        cache.popitem(last=False)
    return value


def proxy_for(robot: Robot, problem: GraspProblem | Sequence[GraspProblem], dtype: torch.dtype = torch.float32,
              device: torch.device | str = "cpu", clearance: float = 0.0, object_tolerance: float = OBJECT_TOLERANCE_M,
              touching: bool = True, fingers_apart: bool = False) -> CollisionProxy:
    """The torch collision proxy of a robot and a problem (or a batch), built once per geometry
    and rule (``object_tolerance``, ``touching``, ``fingers_apart``: :class:`CollisionProxy`)."""
    problems = (problem,) if not isinstance(problem, Sequence) else tuple(problem)
    key = (id(robot), tuple(geometry_key(p) for p in problems), dtype, str(device), clearance, object_tolerance,
           touching, fingers_apart)
    arg = problems[0] if len(problems) == 1 and not isinstance(problem, Sequence) else list(problems)
    return _cached(_PROXIES, key, lambda: CollisionProxy(robot, arg, object_tolerance, dtype=dtype, device=device,
                                                         clearance=clearance, touching=touching,
                                                         fingers_apart=fingers_apart))


def scene_for(robot: Robot, problem: GraspProblem, object_tolerance: float = OBJECT_TOLERANCE_M,
              touching: bool = True, fingers_apart: bool = False) -> CollisionScene:
    """The FCL collision scene of a robot and a problem, built once per geometry and rule
    (``object_tolerance``, ``touching``, ``fingers_apart``: :class:`CollisionScene`)."""
    return _cached(_SCENES, (id(robot), geometry_key(problem), object_tolerance, touching, fingers_apart),
                   lambda: CollisionScene(robot, problem, object_tolerance, touching, fingers_apart))
