"""Two-point grasps for a gripper: antipodal point pairs on the object as wide as its jaws.

A gripper with two marked points (MANUS: jaws that do not move, their marked points
:func:`jaw_width` apart) grasps an object at two surface points where the marked points can meet
them: points that far apart, each pushing into the object within the friction cone. Pairs are
drawn (:func:`antipodal_pairs`): ``samples`` points uniform on the surface (seeded), each put on the
exact surface (:func:`~graspnet_torch.collision.surface.touch_points`: a primitive's, not its
facets'), a ray from it into the object along its inward normal to where it leaves the object
again, that exit put on the exact surface too; a pair is kept where its width is within
``WIDTH_TOL_M`` of the jaws' and the line between its points lies within the friction cone
(``FRICTION``) of both inward normals, ranked by the larger of the two angles (0: the line along
both normals; to 0.1 degree), then by how near the object's centre the pair's midpoint lies (less
torque about the line for the same grip); a pair within ``DISTINCT_M`` of a better one (either
way round) is left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from graspnet_torch.collision.surface import touch_points
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.synthesis.candidates import FRICTION

__all__ = ["WIDTH_TOL_M", "PointPair", "antipodal_pairs", "jaw_width"]

WIDTH_TOL_M = 0.5e-3  # a pair's width within this of the jaws' (the solver lands within 1 mm of d = 0)
SAMPLES = 4096  # surface points drawn per call
DISTINCT_M = 0.01  # a pair within this of a kept one (each point, either way round) is the same pair


@dataclass(frozen=True)
class PointPair:
    """Two points on an object a gripper can pinch.

    Attributes:
        points: (2, 3) the points, world.
        normals: (2, 3) the object's inward unit normals there.
        angles_deg: (2,) each inward normal's angle to the line toward the other point.
    """

    points: np.ndarray
    normals: np.ndarray
    angles_deg: np.ndarray


def jaw_width(robot: Robot) -> float:
    """How far apart a gripper's two marked points are (m; fixed jaws: at any posture)."""
    p = robot.gripper_points(robot.home_posture().body).numpy()
    return float(np.linalg.norm(p[0] - p[1]))


def antipodal_pairs(obj: Shape, width: float, n: int, seed: int = 0, samples: int = SAMPLES,
                    friction: float = FRICTION) -> list[PointPair]:
    """Up to ``n`` antipodal pairs ``width`` (m) apart on ``obj``, best first (module docstring)."""
    import trimesh

    mesh = obj.trimesh()
    drawn, _ = trimesh.sample.sample_surface(mesh, samples, seed=seed)
    p, outward, _ = touch_points(obj, np.asarray(drawn, dtype=np.float64))
    inward = -outward
    origins = p + 1e-6 * inward
    hits, rays, _ = mesh.ray.intersects_location(origins, inward, multiple_hits=False)
    if not len(rays):
        return []
    q, q_out, _ = touch_points(obj, np.asarray(hits, dtype=np.float64))
    p, p_in = p[rays], inward[rays]
    line = q - p
    d = np.linalg.norm(line, axis=1)
    u = line / np.maximum(d, 1e-12)[:, None]
    angles = np.degrees(np.arccos(np.clip(np.stack([np.sum(p_in * u, 1), np.sum(q_out * u, 1)], 1), -1.0, 1.0)))
    cone = math.degrees(math.atan(friction))
    keep = np.flatnonzero((np.abs(d - width) <= WIDTH_TOL_M) & (angles.max(axis=1) <= cone))
    off_centre = np.linalg.norm((p + q) / 2 - np.asarray(obj.pose[:3], dtype=np.float64), axis=1)
    out: list[PointPair] = []
    for k in keep[np.lexsort((off_centre[keep], np.round(angles[keep].max(axis=1), 1)))]:
        pts = np.stack([p[k], q[k]])
        if any(min(np.abs(pts - o.points).max(), np.abs(pts[::-1] - o.points).max()) < DISTINCT_M for o in out):
            continue  # the same pair as one kept (either way round)
        out.append(PointPair(pts, np.stack([p_in[k], -q_out[k]]), angles[k]))
        if len(out) == n:
            break
    return out
