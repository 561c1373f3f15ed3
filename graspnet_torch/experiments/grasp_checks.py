"""What the experiments on synthesized grasps share (``synthesis``, ``hands``): a robot by config
(cached per process), the runs spread over processes, each object's convex decomposition made
before the timed runs, and what is recomputed of a reported grasp independently of the synthesis:
the deepest any link lies inside the object (FCL, no link exempt) and how far from the object the
links it says touch are (FCL)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision.convex import convex_pieces
from graspnet_torch.collision.geometry import fcl_geometry, fcl_transform, link_geometry, mesh_bvh
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.experiments.report import progress
from graspnet_torch.meshes import mesh_path
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver.postures import trial_posture

__all__ = ["decompose_s", "depth_mm", "holds_text", "link_gap_mm", "map_jobs", "robot_of"]


@lru_cache(maxsize=16)
def robot_of(config: str) -> gt.Robot:
    """A robot by a shipped name or a YAML path (relative to the repository), loaded once per process."""
    return gt.load_robot(repo_root() / config if config.endswith(".yaml") else config)


def depth_mm(robot: gt.Robot, grasp: Any) -> float:
    """The deepest any link of a reported grasp lies inside the object (FCL, no link exempt)."""
    posture = trial_posture(robot, grasp.result.best)
    report = CollisionScene(robot, grasp.problem, object_tolerance=0.0, touching=False).check(posture)
    return max(report.object_links.values(), default=0.0) * 1000


def link_gap_mm(robot: gt.Robot, grasp: Any, links: Sequence[str]) -> float:
    """The farthest of ``links`` from the object at the grasp's posture (mm; 0: touching or inside):
    each link's nearest collision shape, placed by the robot's kinematics, against the object (FCL
    distance; a surface mesh crossing the object counts 0)."""
    import fcl

    obj = grasp.problem.object
    geometry = mesh_bvh(mesh_path(obj.mesh), obj.scale) if obj.kind == "mesh" else fcl_geometry(obj.kind, obj.size)
    target = fcl.CollisionObject(geometry, fcl_transform(pose_to_matrix_np(obj.pose)))
    names, frames = robot.link_frames_array([trial_posture(robot, grasp.result.best)])
    row = {name: k for k, name in enumerate(names)}
    gaps = {link: np.inf for link in links}
    for s in link_shapes(robot.urdf, "collision"):
        if s.link in gaps and s.link in row:
            placed = fcl.CollisionObject(link_geometry(s), fcl_transform(frames[0, row[s.link]] @ s.origin))
            d = fcl.distance(placed, target, fcl.DistanceRequest(), fcl.DistanceResult())
            gaps[s.link] = min(gaps[s.link], max(float(d), 0.0))
    return max(gaps.values(), default=0.0) * 1000


def holds_text(grasp: Any) -> str:
    """A grasp's physics check in words: not checked, holds 6/6, or the push that failed."""
    if grasp.physics is None:
        return "not checked"
    return "holds 6/6" if grasp.physics.held_all else f"fails push {len(grasp.physics.directions)}"


def decompose_s(obj: Shape) -> float:
    """The seconds an object's convex decomposition takes (cached on disk: 0 where it was;
    a primitive has none)."""
    if obj.kind != "mesh":
        return 0.0
    t0 = time.perf_counter()
    convex_pieces(obj.mesh, obj.scale)
    return time.perf_counter() - t0


def map_jobs(fn: Callable[..., Any], args: list[tuple], jobs: int, desc: str | None = None,
             unit: str = "object") -> list:
    """``fn(*a)`` for each of ``args``, in order: in this process, or in ``jobs`` joblib processes;
    with a progress bar where ``desc`` is given."""
    if jobs == 1:
        calls = (fn(*a) for a in args)
    else:
        from joblib import Parallel, delayed

        calls = Parallel(n_jobs=jobs, return_as="generator")(delayed(fn)(*a) for a in args)
    return list(calls if desc is None else progress(calls, total=len(args), desc=desc, unit=unit))
