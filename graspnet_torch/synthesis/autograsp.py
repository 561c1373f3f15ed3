"""Closing a hand onto an object with no contact reasoning (GraspIt!'s "autograsp", Miller and
Allen 2004): each finger's joints move in their closing direction (:func:`closing_signs`) in
lockstep along a straight line in joint space and a finger stops where any of its links first
meets the object's surface (:func:`close_fingers`), its links as spheres and points
(:func:`finger_spheres`); the planner of :mod:`~graspnet_torch.synthesis.baseline` and the wrap
grasps of :mod:`~graspnet_torch.synthesis.power` close fingers so.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from graspnet_torch.collision.scene import finger_pairs
from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.collision.surface import (
    surface_distance,
    surface_distance_near,
    surface_distance_within,
    surface_normals,
)
from graspnet_torch.robot.geometry import link_shapes, surface_points
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import place_points_np
from graspnet_torch.solver import GraspResult
from graspnet_torch.solver.contact import posture_fields
from graspnet_torch.solver.result import TrialResult
from graspnet_torch.synthesis.closing import tip_jacobians

__all__ = ["FORWARD", "TOUCH_M", "close_fingers", "closed_result", "closing_signs", "finger_gaps", "finger_spheres",
           "link_contacts", "nearest_contacts", "placed_spheres", "sphere_pairs"]

STEPS = 24  # samples of each finger's closing line
BISECT = 14  # bisection steps after the first sample that touches
FORWARD = 0.3  # a joint closes when its tip motion's cosine to the palm's front axis is at least this (or -this)
TOUCH_M = 1e-3  # a finger touches when a link lies within this of the surface
RIM = 12  # points around each of a cylinder's rims
LINK_POINTS = 128  # points spread over each link shape where link_contacts measures it


def finger_spheres(robot: Robot, surface: bool = False, points: int = 0
                   ) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray]:
    """Every finger link's collision shapes as spheres (:func:`shape_spheres`): the finger row of
    each sphere (s,), the link row of each (into ``robot.link_frames_of``'s names), centres (s, 3)
    in the link frame, radii (s,). ``surface``: a cylinder (radius r, length L) instead as spheres of
    radius r inside it (centres along its axis up to L/2 - r, r/2 apart) and points of its surface
    (radius 0) where those miss it: ``RIM`` around its flat ends' rims and around the circles
    halfway from there to the last sphere's centre; :func:`shape_spheres` overshoot its ends by 3r/4.
    ``points`` > 0 (with ``surface``): boxes and meshes as points of their surface (radius 0), their
    vertices and ``points`` more (a box's spheres miss its corners, a mesh's stand out of it)."""
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
        elif surface and points and shape.kind in ("box", "mesh"):
            c = surface_points(shape, shape.origin, points, points)
            rad = np.zeros(len(c))
        else:
            c, rad = shape_spheres(shape)
        rows += [owner[shape.link]] * len(rad)
        links += [names.index(shape.link)] * len(rad)
        centres.append(c)
        radii.append(rad)
    return np.asarray(rows), links, np.concatenate(centres), np.concatenate(radii)


def sphere_pairs(robot: Robot, spheres: tuple) -> tuple[np.ndarray, np.ndarray]:
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


def placed_spheres(frames: np.ndarray, model: tuple) -> np.ndarray:
    """(B, s, 3) a sphere model's centres in the world; frames (B, L, 4, 4)."""
    links, centres = np.asarray(model[1]), model[2]
    out = np.empty((len(frames), len(links), 3))
    for link in np.unique(links):  # one product per link: its centres (k, 3) by its frames (B, 3, 3)
        rows = np.flatnonzero(links == link)
        out[:, rows] = place_points_np(frames[:, link], centres[rows])
    return out


def finger_gaps(robot: Robot, obj: Shape, head: torch.Tensor, q: torch.Tensor, models: tuple,
                pairs: tuple[np.ndarray, np.ndarray] | None = None, mask: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """Each finger's least clearance (B, F) (m; negative: how deep) from the object, its links as
    ``models[0]`` (:func:`finger_spheres`; ``mask`` (B, s): only the spheres it marks), and (with
    ``pairs``) the clearance (B, P) of each pair of ``models[1]``'s spheres: head (B, 6), q (B, F, n)."""
    rows, _, _, radii = models[0]
    _, frames = robot.link_frames_of(None, q, head)
    gap = surface_distance_near(obj, placed_spheres(frames, models[0]).reshape(-1, 3)).reshape(len(q), -1) - radii
    if mask is not None:
        gap = np.where(mask, gap, np.inf)
    out = np.full((len(q), q.shape[1]), np.inf)
    for f in range(q.shape[1]):
        if np.any(rows == f):
            out[:, f] = gap[:, rows == f].min(axis=1)
    if pairs is None:
        return out, None
    (i, j), world, r = pairs, placed_spheres(frames, models[1]), models[1][3]
    return out, np.linalg.norm(world[:, i] - world[:, j], axis=-1) - r[i] - r[j]


def closing_signs(robot: Robot, q_open: np.ndarray, front: np.ndarray) -> np.ndarray:
    """(B, F, n) each joint's closing direction (+1 up, -1 down, 0 held) at the open postures
    q_open (B, F, n): the sign of its tip motion along the palm's front axis, where its cosine
    reaches ``FORWARD`` (module docstring, step 2)."""
    J = tip_jacobians(robot, q_open)  # (B, F, 3, n)
    length = np.linalg.norm(J, axis=-2)
    cos = np.einsum("i,bfij->bfj", front, J) / np.maximum(length, 1e-9) * (length > 1e-9)
    return np.where(cos >= FORWARD, 1.0, np.where(cos <= -FORWARD, -1.0, 0.0))


def close_fingers(robot: Robot, obj: Shape, head: torch.Tensor, q_open: torch.Tensor, q_close: torch.Tensor,
                  spheres: tuple, pairs: tuple[np.ndarray, np.ndarray], mask: np.ndarray | None = None
                  ) -> tuple[torch.Tensor, np.ndarray]:
    """Every finger closed in lockstep along its line until a link meets the object (then bisected
    to the touch) or another finger (then back one sample): head (B, 6), q_open / q_close
    (B, F, n) -> the joints (B, F, n) and each finger's clearance from the object there (B, F);
    ``mask`` (B, s): only the spheres of ``spheres[0]`` it marks count as meeting the object."""
    B, F, _ = q_open.shape
    ts = np.linspace(0.0, 1.0, STEPS)
    dq = q_close - q_open
    gap, apart = finger_gaps(robot, obj, head, q_open, spheres, pairs, mask)
    free = apart > 0  # (B, P) sphere pairs apart at the open posture: they may not meet
    t = np.zeros((B, F))
    hit = gap <= 0  # (B, F): met the object between t - 1 / (STEPS - 1) and t (at t = 0: already)
    active = ~hit
    lo = np.zeros((B, F))
    i, j = spheres[1][0][pairs[0]], spheres[1][0][pairs[1]]  # (P,) the fingers of each pair's spheres
    for s in range(1, STEPS):
        trial = np.where(active, ts[s], t)
        gap, apart = finger_gaps(robot, obj, head, q_open + torch.as_tensor(trial)[..., None] * dq, spheres, pairs,
                                 mask)
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
        g, _ = finger_gaps(robot, obj, head, q_open + torch.as_tensor(mid)[..., None] * dq, spheres, mask=mask)
        lo, hi = np.where(moving & (g > 0), mid, lo), np.where(moving & (g <= 0), mid, hi)
    t = np.where(moving, hi, t)
    q = q_open + torch.as_tensor(t)[..., None] * dq
    return q, finger_gaps(robot, obj, head, q, spheres, mask=mask)[0]


def nearest_contacts(robot: Robot, obj: Shape, posture: Posture, fingers: tuple[str, ...], model: tuple
                     ) -> np.ndarray:
    """(k, 3) world: for each touching finger, the surface point nearest its nearest sphere or point."""
    rows, _, _, radii = model
    _, frames = robot.link_frames_of(None, posture.fingers[None], posture.palm_pose[None])
    world = placed_spheres(frames, model)[0]
    gap = surface_distance(obj, world) - radii
    nearest = world[[np.flatnonzero(rows == robot.finger_index(f))[np.argmin(gap[rows == robot.finger_index(f)])]
                     for f in fingers]]
    return nearest - surface_distance(obj, nearest)[:, None] * surface_normals(obj, nearest)


def closed_result(robot: Robot, posture: Posture, squeeze: np.ndarray, seed: int) -> GraspResult:
    """A closed posture as a one-trial :class:`GraspResult` whose ``squeeze`` (what a physics
    check commands) holds the fingers at ``squeeze`` (F, n), the palm where ``posture`` has it."""
    closer = Posture(palm_pose=posture.palm_pose, fingers=torch.as_tensor(squeeze), body=posture.body)
    trial = TrialResult(True, 0, 0.0, 0.0, 0, 0.0, **posture_fields(robot, posture),
                        squeeze=posture_fields(robot, closer))
    return GraspResult(robot.cfg.name, [trial], seed=seed)


def link_contacts(robot: Robot, obj: Shape, posture: Posture, within_m: float) -> tuple[tuple[str, ...], np.ndarray]:
    """The links (palm and fingers, in the URDF's order) with a point of their collision surface
    within ``within_m`` of ``obj``'s surface, on either side of it, at ``posture`` (``LINK_POINTS``
    points per shape and its vertices: a link listed lies that near; one that touches between its
    points may be left out), and for
    each the point of the object's surface (its triangulation, ``obj.trimesh()``) nearest its
    nearest point (k, 3), world."""
    names, frames = robot.link_frames_of(None, posture.fingers[None], posture.palm_pose[None])
    nearest: dict[str, tuple[float, np.ndarray]] = {}
    for shape in link_shapes(robot.urdf):
        if shape.link not in names:
            continue
        points = surface_points(shape, frames[0, names.index(shape.link)] @ shape.origin, LINK_POINTS,
                                LINK_POINTS)
        gap = np.abs(surface_distance_within(obj, points, within_m))  # either side: a mesh's inside test can err
        i = int(np.argmin(gap))
        if gap[i] <= within_m and gap[i] < nearest.get(shape.link, (np.inf, None))[0]:
            nearest[shape.link] = (float(gap[i]), points[i])
    if not nearest:
        return (), np.zeros((0, 3))
    import trimesh

    at = np.stack([p for _, p in nearest.values()])
    return tuple(nearest), np.asarray(trimesh.proximity.closest_point(obj.trimesh(), at)[0], dtype=np.float64)
