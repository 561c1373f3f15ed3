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
   :func:`_finger_spheres`), found by
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
from graspnet_torch.collision.scene import finger_pairs
from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.collision.surface import surface_distance, surface_distance_near, surface_normals
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose_np, pose_to_matrix_np
from graspnet_torch.solver import GraspResult
from graspnet_torch.solver.api import as_robot
from graspnet_torch.solver.contact import posture_fields
from graspnet_torch.solver.result import TrialResult
from graspnet_torch.synthesis.candidates import placeholder_problem
from graspnet_torch.synthesis.closing import tip_jacobians
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["GAP_M", "MIN_TOUCHING", "OPEN", "PENETRATION_M", "SQUEEZE_DEG", "TOUCH_M", "BaselineGrasp",
           "baseline_grasps"]

STEPS = 24  # samples of each finger's closing line
BISECT = 14  # bisection steps after the first sample that touches
OPEN = (0.0, 0.2)  # a finger's open posture: this fraction of each joint's range above its lower limit
GAP_M = (0.0, 0.02)  # the object's gap to the palm's face along the front axis
FORWARD = 0.3  # a joint closes when its tip motion's cosine to the palm's front axis is at least this (or -this)
TOUCH_M = 1e-3  # a finger touches when a link lies within this of the surface
PENETRATION_M = 1e-3  # no link deeper than this in the object
MIN_TOUCHING = 2  # fingers that must touch
SQUEEZE_DEG = 5.0  # the squeeze: each closing joint this much further
RIM = 12  # points around each of a cylinder's rims


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


def _finger_spheres(robot: Robot, surface: bool = False) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray]:
    """Every finger link's collision shapes as spheres (:func:`shape_spheres`): the finger row of
    each sphere (s,), the link row of each (into ``robot.link_frames_of``'s names), centres (s, 3)
    in the link frame, radii (s,). ``surface``: a cylinder (radius r, length L) instead as spheres of
    radius r inside it (centres along its axis up to L/2 - r, r/2 apart) and points of its surface
    (radius 0) where those miss it: ``RIM`` around its flat ends' rims and around the circles
    halfway from there to the last sphere's centre; :func:`shape_spheres` overshoot its ends by 3r/4."""
    owner = {}
    for i, finger in enumerate(robot.fingers.values()):
        for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip):
            owner[joint.child] = i
    names, _ = robot.link_frames_of(None, robot.home_posture().fingers[None], torch.zeros(1, 6, dtype=torch.float64))
    rows, links, centres, radii = [], [], [], []
    for shape in link_shapes(robot.urdf):
        if shape.link not in owner:
            continue
        if surface and shape.shape.kind == "cylinder":
            r, length = shape.shape.size
            inner = max(length / 2 - r, 0.0)  # spheres inside it, points around its ends
            z = np.linspace(-inner, inner, max(2, math.ceil(2 * inner / (r / 2)) + 1))
            a, h = np.meshgrid(np.linspace(0, 2 * np.pi, RIM, endpoint=False),
                               [-length / 2, -(length / 2 + inner) / 2, (length / 2 + inner) / 2, length / 2])
            local = np.concatenate([np.stack([0 * z, 0 * z, z], axis=1),
                                    np.stack([r * np.cos(a), r * np.sin(a), h], axis=-1).reshape(-1, 3)])
            c = local @ shape.origin[:3, :3].T + shape.origin[:3, 3]
            rad = np.concatenate([np.full(len(z), min(r, length / 2)), np.zeros(a.size)])
        else:
            c, rad = shape_spheres(shape)
        rows += [owner[shape.link]] * len(rad)
        links += [names.index(shape.link)] * len(rad)
        centres.append(c)
        radii.append(rad)
    return np.asarray(rows), links, np.concatenate(centres), np.concatenate(radii)


def _sphere_pairs(robot: Robot, spheres: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The sphere pairs (P,), (P,) of two fingers' links that may not meet
    (:func:`~graspnet_torch.collision.scene.finger_pairs`)."""
    names, _ = robot.link_frames_of(None, robot.home_posture().fingers[None], torch.zeros(1, 6, dtype=torch.float64))
    links = np.asarray(spheres[1])
    first, second = [], []
    for a, b in finger_pairs(robot):
        i, j = np.flatnonzero(links == names.index(a)), np.flatnonzero(links == names.index(b))
        first.append(np.repeat(i, len(j)))
        second.append(np.tile(j, len(i)))
    return (np.concatenate(first), np.concatenate(second)) if first else (np.zeros(0, int), np.zeros(0, int))


def _placed(frames: np.ndarray, model: tuple) -> np.ndarray:
    """(B, s, 3) a sphere model's centres in the world; frames (B, L, 4, 4)."""
    T = frames[:, model[1]]  # (B, s, 4, 4)
    return np.einsum("bsij,sj->bsi", T[..., :3, :3], model[2]) + T[..., :3, 3]


def _gaps(robot: Robot, obj: Shape, head: torch.Tensor, q: torch.Tensor, models: tuple,
          pairs: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Each finger's least clearance (B, F) (m; negative: how deep) from the object, its links as
    ``models[0]`` (:func:`_finger_spheres`), and (with ``pairs``) the clearance (B, P) of each pair
    of ``models[1]``'s spheres: head (B, 6), q (B, F, n)."""
    rows, _, _, radii = models[0]
    _, frames = robot.link_frames_of(None, q, head)
    gap = surface_distance_near(obj, _placed(frames, models[0]).reshape(-1, 3)).reshape(len(q), -1) - radii
    out = np.full((len(q), q.shape[1]), np.inf)
    for f in range(q.shape[1]):
        if np.any(rows == f):
            out[:, f] = gap[:, rows == f].min(axis=1)
    if pairs is None:
        return out, None
    (i, j), world, r = pairs, _placed(frames, models[1]), models[1][3]
    return out, np.linalg.norm(world[:, i] - world[:, j], axis=-1) - r[i] - r[j]


def _closing(robot: Robot, q_open: np.ndarray, front: np.ndarray) -> np.ndarray:
    """(B, F, n) each joint's closing direction (+1 up, -1 down, 0 held) at the open postures
    q_open (B, F, n): the sign of its tip motion along the palm's front axis, where its cosine
    reaches ``FORWARD`` (module docstring, step 2)."""
    J = tip_jacobians(robot, q_open)  # (B, F, 3, n)
    length = np.linalg.norm(J, axis=-2)
    cos = np.einsum("i,bfij->bfj", front, J) / np.maximum(length, 1e-9) * (length > 1e-9)
    return np.where(cos >= FORWARD, 1.0, np.where(cos <= -FORWARD, -1.0, 0.0))


def _close(robot: Robot, obj: Shape, head: torch.Tensor, q_open: torch.Tensor, q_close: torch.Tensor,
           spheres: tuple, pairs: tuple[np.ndarray, np.ndarray]) -> tuple[torch.Tensor, np.ndarray]:
    """Every finger closed in lockstep along its line until a link meets the object (then bisected
    to the touch) or another finger (then back one sample): head (B, 6), q_open / q_close
    (B, F, n) -> the joints (B, F, n) and each finger's clearance from the object there (B, F)."""
    B, F, _ = q_open.shape
    ts = np.linspace(0.0, 1.0, STEPS)
    dq = q_close - q_open
    gap, apart = _gaps(robot, obj, head, q_open, spheres, pairs)
    free = apart > 0  # (B, P) sphere pairs apart at the open posture: they may not meet
    t = np.zeros((B, F))
    hit = gap <= 0  # (B, F): met the object between t - 1 / (STEPS - 1) and t (at t = 0: already)
    active = ~hit
    lo = np.zeros((B, F))
    i, j = spheres[1][0][pairs[0]], spheres[1][0][pairs[1]]  # (P,) the fingers of each pair's spheres
    for s in range(1, STEPS):
        trial = np.where(active, ts[s], t)
        gap, apart = _gaps(robot, obj, head, q_open + torch.as_tensor(trial)[..., None] * dq, spheres, pairs)
        meet = free & (apart <= 0)
        blocked = np.zeros((B, F), dtype=bool)
        for f in range(F):
            blocked[:, f] = (meet & ((i == f) | (j == f))).any(axis=1)
        touched = active & (gap <= 0)
        hit |= touched
        lo = np.where(touched, ts[s - 1], lo)
        t = np.where(touched, ts[s], np.where(active & ~blocked, ts[s], t))
        active &= ~touched & ~blocked
    hi = t.copy()
    moving = hit & (t > 0)
    for _ in range(BISECT):  # the first touch: gap(lo) > 0 >= gap(hi)
        mid = np.where(moving, (lo + hi) / 2, t)
        g, _ = _gaps(robot, obj, head, q_open + torch.as_tensor(mid)[..., None] * dq, spheres)
        lo, hi = np.where(moving & (g > 0), mid, lo), np.where(moving & (g <= 0), mid, hi)
    t = np.where(moving, hi, t)
    q = q_open + torch.as_tensor(t)[..., None] * dq
    return q, _gaps(robot, obj, head, q, spheres)[0]


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
    ``physics_s`` and ``held_physics_s`` (s; the part spent on the checks that held). Measured on the shipped
    hand, 64 candidates, seed 0, one thread, with ``gt.simulate_grasp``: see the report of the
    commit that added this module.
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
    spheres = _finger_spheres(robot, surface=True), _finger_spheres(robot)
    pairs = _sphere_pairs(robot, spheres[1])
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
    direction = _closing(robot, q_open, front)
    q_close = np.where(direction > 0, hi, np.where(direction < 0, lo, q_open))
    q, gaps = _close(robot, obj, head, torch.as_tensor(q_open), torch.as_tensor(q_close), spheres, pairs)
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
        closer = torch.as_tensor(np.clip(q[b].numpy() + step * direction[b], lo, hi))
        squeeze = Posture(palm_pose=posture.palm_pose, fingers=closer, body=posture.body)
        problem = placeholder_problem(robot, obj, fingers, _contacts(robot, obj, posture, fingers, spheres[0]))
        trial = TrialResult(True, 0, 0.0, 0.0, 0, 0.0, **posture_fields(robot, posture),
                            squeeze=posture_fields(robot, squeeze))
        grasps.append(BaselineGrasp(problem, posture, fingers, GraspResult(robot.cfg.name, [trial], seed=seed)))
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


def _contacts(robot: Robot, obj: Shape, posture: Posture, fingers: tuple[str, ...], model: tuple) -> np.ndarray:
    """(k, 3) world: for each touching finger, the surface point nearest its nearest sphere or point."""
    rows, _, _, radii = model
    _, frames = robot.link_frames_of(None, posture.fingers[None], posture.palm_pose[None])
    world = _placed(frames, model)[0]
    gap = surface_distance(obj, world) - radii
    nearest = world[[np.flatnonzero(rows == robot.finger_index(f))[np.argmin(gap[rows == robot.finger_index(f)])]
                     for f in fingers]]
    return nearest - surface_distance(obj, nearest)[:, None] * surface_normals(obj, nearest)
