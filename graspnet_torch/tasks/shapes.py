"""Shapes of grasp problems: a problem's obstacles and the checks that involve its shapes (an
obstacle that swallows a contact).

A shape itself (an object or obstacle: kind, size, pose, mesh file) is the package's one
:class:`~graspnet_torch.robot.shape.Shape`, read from and written to problem files there. Every
refusal is a :class:`~graspnet_torch.errors.ProblemError` with one line that names the file and the
offending entry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import rpy_to_matrix_np

__all__ = ["MAX_OBSTACLES", "check_free_contacts", "inside", "obstacles_of"]

MAX_OBSTACLES = 1000


def obstacles_of(data: Mapping, source: str, shape: dict) -> tuple[Shape, ...]:
    """The problem's ``obstacles``: a list of at most :data:`MAX_OBSTACLES` shapes."""
    obstacles = data.get("obstacles")
    obstacles = [] if obstacles is None else obstacles
    if not isinstance(obstacles, list):
        raise ProblemError(f"{source}: 'obstacles' must be a list of shapes")
    if len(obstacles) > MAX_OBSTACLES:
        raise ProblemError(f"{source}: obstacles: {len(obstacles)} shapes, at most {MAX_OBSTACLES} allowed")
    return tuple(Shape.from_mapping(o, f"{source}: obstacles[{k}]", **shape) for k, o in enumerate(obstacles))


def inside(shape: Shape, points: np.ndarray) -> np.ndarray:
    """(N,) whether world points lie inside a shape (closed primitives; a mesh by trimesh)."""
    if shape.kind == "mesh":
        return np.asarray(shape.trimesh().contains(points), dtype=bool)
    p = (points - shape.pose[:3]) @ rpy_to_matrix_np(shape.pose[3:])  # into the shape's frame
    if shape.kind == "box":
        return np.all(np.abs(p) < np.asarray(shape.size) / 2, axis=1)
    if shape.kind == "cylinder":
        return (np.linalg.norm(p[:, :2], axis=1) < shape.size[0]) & (np.abs(p[:, 2]) < shape.size[1] / 2)
    return np.linalg.norm(p, axis=1) < shape.size[0]


def check_free_contacts(obstacles: Sequence[Shape], fingers: Sequence[str], positions: np.ndarray,
                        obj: Shape | None, source: str) -> None:
    """Refuse an obstacle that swallows a contact (``positions``: (F, 3) in the object frame, one
    per finger of ``fingers``): no fingertip could touch it collision-free."""
    points = np.asarray(positions, dtype=np.float64)
    if obj is not None:
        points = points @ rpy_to_matrix_np(obj.pose[3:]).T + obj.pose[:3]
    for k, shape in enumerate(obstacles):
        hit = inside(shape, points)
        if hit.any():
            names = ", ".join(fingers[i] for i in np.nonzero(hit)[0])
            raise ProblemError(f"{source}: obstacles[{k}] ({shape.kind}) contains the {names} contact: no "
                               f"fingertip can reach it without a collision")

