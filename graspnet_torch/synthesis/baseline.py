"""A grasp planner without contact reasoning, to stand beside the contact-based synthesis
(:func:`~graspnet_torch.synthesis.synthesize.synthesize_grasps`) on the same objects.

The model is GraspIt!'s default planner: put the palm near the object, facing it, and close every
finger until it touches ("autograsp", Miller and Allen 2004: each DOF moves in its closing
direction and a link stops where it meets the object). No contact point, pad or normal is chosen;
whatever the fingers meet is the grasp. One candidate, every candidate of a call in one batch:

1. *Palm*: a uniformly random palm orientation (a random approach direction and roll); the palm's
   front axis (the palm collision box's thinnest axis, on the fingers' side) points at the object's
   centre from a random point of the plane of the palm's face within the fingertips' reach (the
   box around the fingertips at the joints' lower and upper limits, on that plane), the object a
   random gap (``GAP_M``) in front of the face (between the face and its nearest point).
2. *Fingers*: each finger starts open (``OPEN``: a random fraction of each joint's range above its
   lower limit) and closes along a straight line in joint space: a joint whose increase moves the
   fingertip towards the palm's front (the tip's Jacobian column at the open posture, over its
   length, dotted with the front axis at least ``FORWARD``) runs up to its upper limit, one that
   moves it away (at most ``-FORWARD``) down to its lower limit, one that moves it sideways (an
   abduction) is held where it opened. Every finger moves in lockstep over ``STEPS`` samples of its
   line; a finger stops where any of its links first meets the object's surface
   (:func:`~graspnet_torch.collision.surface.surface_distance_near`, the sampler's fast distance,
   of its collision shapes as spheres and, around a cylinder's ends, points of its surface:
   :func:`~graspnet_torch.synthesis.autograsp.finger_spheres`), found by
   bisection, or one sample before a link meets another finger's link
   (:func:`~graspnet_torch.collision.spheres.shape_spheres`, the pairs of
   :func:`~graspnet_torch.collision.scene.finger_pairs`), or at the line's end (touching nothing).
   Unlike GraspIt!, the joints beyond a touching link stop too.
3. *Check*: kept where at least ``MIN_TOUCHING`` fingers touch (a link within ``TOUCH_M`` of the
   surface; the thumb among them where the hand's first finger is the thumb) and the FCL scene
   (:class:`~graspnet_torch.collision.scene.CollisionScene`: every link, the fingers apart) finds
   no link deeper than ``PENETRATION_M`` in the object and no link through another.

The grasp is the touching posture; its squeeze (what a physics check commands) closes every
closing joint ``SQUEEZE_DEG`` further, within its limits. Everything is drawn from one ``numpy``
generator seeded by ``seed``: the same call gives the same grasps.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose_np, pose_to_matrix_np
from graspnet_torch.solver import GraspResult
from graspnet_torch.solver.api import as_robot
from graspnet_torch.synthesis.autograsp import (
    TOUCH_M,
    close_fingers,
    closed_result,
    closing_signs,
    finger_spheres,
    nearest_contacts,
    sphere_pairs,
)
from graspnet_torch.synthesis.candidates import placeholder_problem
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["GAP_M", "MIN_TOUCHING", "OPEN", "PENETRATION_M", "SQUEEZE_DEG", "TOUCH_M", "BaselineGrasp",
           "baseline_grasps"]

OPEN = (0.0, 0.2)  # a finger's open posture: this fraction of each joint's range above its lower limit
GAP_M = (0.0, 0.02)  # the object's gap to the palm's face along the front axis
PENETRATION_M = 1e-3  # no link deeper than this in the object
MIN_TOUCHING = 2  # fingers that must touch
SQUEEZE_DEG = 5.0  # the squeeze: each closing joint this much further


@dataclass
class BaselineGrasp:
    """One grasp of the approach-and-close planner.

    Attributes:
        problem: a problem of the robot holding the object (the touching fingers, each contact the
            surface point nearest its touching link, object frame): what a physics check takes.
        posture: the closed hand (palm pose (6,), fingers (F, n)).
        touching: the fingers that touch the object, in the robot's order.
        result: a one-trial :class:`GraspResult` of ``posture``, its ``squeeze`` the posture closed
            further (``gt.simulate_grasp`` takes it).
        physics: the physics check of ``result`` (a :class:`gt.PhysicsReport`; None: not asked for).
    """

    problem: GraspProblem
    posture: Posture
    touching: tuple[str, ...]
    result: GraspResult
    physics: Any = None

    @property
    def holds(self) -> int | None:
        """Of the physics check's pushes, how many held (None: not checked)."""
        return None if self.physics is None else sum(self.physics.directions.values())


def _palm_face(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The palm's face, palm frame: its front axis (3,) (the palm box's thinnest axis, on the home
    fingertips' side), a point of it (3,) and its two in-plane axes (3, 2) (no box: +y through the
    origin)."""
    tips = robot.fingertips_palm(robot.home_posture().fingers).numpy().mean(axis=0)
    box = next((s.shape for s in link_shapes(robot.urdf) if s.link == robot.cfg.palm_link and s.shape.kind == "box"),
               None)
    if box is None:
        return np.array([0.0, 1.0, 0.0]), np.zeros(3), np.eye(3)[:, [0, 2]]
    R = pose_to_matrix_np(box.pose)[:3, :3]
    axis = int(np.argmin(box.size))
    front = R[:, axis] * (1.0 if R[:, axis] @ (tips - box.pose[:3]) >= 0 else -1.0)
    return front, box.pose[:3] + front * box.size[axis] / 2, R[:, [i for i in range(3) if i != axis]]


def baseline_grasps(robot: Robot | RobotCfg | str | Path, obj: Shape, n_grasps: int = 5, candidates: int = 64,
                    seed: int = 0, physics: Callable[..., Any] | None = None, check_top: int | None = None,
                    stats: dict | None = None) -> list[BaselineGrasp]:
    """Up to ``n_grasps`` grasps of ``obj`` by ``robot`` (a built robot, a shipped robot's name, a
    robot config or its YAML path) from ``candidates`` random palm poses, each closed onto the
    object with no contact reasoning (module docstring), best first.

    Ranked by how many fingers touch (more first); where ``physics`` (a check
    ``physics(problem, result, robot=robot)`` returning a report with ``directions``, i.e.
    ``gt.simulate_grasp``: this layer sits below the physics layer) is given, the best
    ``check_top`` (default: every kept grasp) by that rank are checked and ranked by touching
    fingers, then pushes held (the unchecked ones dropped). ``stats``, if given, receives ``tried``
    (palm poses), ``touching`` (enough fingers touch), ``clean`` (and FCL-clean: the grasps kept),
    ``checked``, ``held`` (of those, holding every push) and the timings ``close_s``, ``check_s``,
    ``physics_s`` and ``held_physics_s`` (s; the part spent on the checks that held).
    """
    robot = as_robot(robot)
    if robot.has_body or robot.shared.n:
        raise ProblemError(f"{robot.cfg.name}: baseline_grasps places a free hand's palm (no arm, no shared joints)")
    if n_grasps < 1 or candidates < 1:
        raise ProblemError(f"baseline_grasps: n_grasps {n_grasps} and candidates {candidates} must be >= 1")
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    names = list(robot.fingers)
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    span = hi - lo
    front, face, plane = _palm_face(robot)
    spheres = finger_spheres(robot, surface=True), finger_spheres(robot)
    pairs = sphere_pairs(robot, spheres[1])
    verts = np.asarray(obj.trimesh().vertices, dtype=np.float64)
    centre = np.asarray(obj.pose[:3], dtype=np.float64)
    B = candidates
    R = Rotation.random(B, random_state=rng).as_matrix()  # (B, 3, 3) palm orientations: approach and roll
    tips = np.concatenate([robot.fingertips_palm(torch.as_tensor(a)).numpy() for a in (lo, hi)]) @ plane  # (2F, 2)
    spot = (face @ front) * front + (tips.min(axis=0) + rng.random((B, 2)) * np.ptp(tips, axis=0)) @ plane.T
    gap = rng.uniform(*GAP_M, B)
    d = np.einsum("bij,j->bi", R, front)  # world: the palm's front axis, towards the object
    reach = ((verts - centre) @ -d.T).max(axis=0)  # how far the object reaches back towards the palm
    T = np.tile(np.eye(4), (B, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = centre - (reach + gap)[:, None] * d - np.einsum("bij,bj->bi", R, spot)
    head = torch.as_tensor(np.stack([matrix_to_pose_np(t) for t in T]))
    q_open = lo + rng.uniform(*OPEN, (B, *lo.shape)) * span
    direction = closing_signs(robot, q_open, front)
    q_close = np.where(direction > 0, hi, np.where(direction < 0, lo, q_open))
    q, gaps = close_fingers(robot, obj, head, torch.as_tensor(q_open), torch.as_tensor(q_close), spheres, pairs)
    touch = (gaps <= TOUCH_M) & (gaps >= -PENETRATION_M)  # (B, F)
    enough = touch.sum(axis=1) >= MIN_TOUCHING
    if names[0] == "thumb":
        enough &= touch[:, 0]
    t1 = time.perf_counter()
    scene = scene_for(robot, placeholder_problem(robot, obj, names[:2]), PENETRATION_M, False, fingers_apart=True)
    rows = np.flatnonzero(enough)
    postures = [Posture(palm_pose=head[b], fingers=q[b], body=torch.zeros(0, dtype=torch.float64)) for b in rows]
    clean = [k for k, rep in enumerate(scene.check_many(postures)) if rep.count == 0] if postures else []
    step = math.radians(SQUEEZE_DEG)
    grasps = []
    for k in clean:
        b, posture = rows[k], postures[k]
        fingers = tuple(f for f, on in zip(names, touch[b], strict=True) if on)
        result = closed_result(robot, posture, np.clip(q[b].numpy() + step * direction[b], lo, hi), seed)
        problem = placeholder_problem(robot, obj, fingers, nearest_contacts(robot, obj, posture, fingers, spheres[0]))
        grasps.append(BaselineGrasp(problem, posture, fingers, result))
    grasps.sort(key=lambda g: -len(g.touching))  # stable: draw order within a count
    t2 = time.perf_counter()
    held, held_s = 0, 0.0
    if physics is not None:
        grasps = grasps[:check_top]
        for g in grasps:
            t4 = time.perf_counter()
            g.physics = physics(g.problem, g.result, robot=robot)
            if g.holds == g.physics.of:
                held, held_s = held + 1, held_s + time.perf_counter() - t4
        grasps.sort(key=lambda g: (-len(g.touching), -(g.holds or 0)))
    t3 = time.perf_counter()
    if stats is not None:
        stats.update(tried=B, touching=int(enough.sum()), clean=len(clean),
                     checked=len(grasps) if physics is not None else 0, held=held, close_s=t1 - t0,
                     check_s=t2 - t1, physics_s=t3 - t2, held_physics_s=held_s)
    return grasps[:n_grasps]
