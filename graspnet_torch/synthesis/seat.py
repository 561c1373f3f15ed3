"""Pads seated on the surface: a precision grasp whose pad links stand off the object.

The surface contact model (:func:`~graspnet_torch.collision.surface.pad_targets`) puts each tip
frame at ``c + depth n`` (c: the contact, n: the object's outward normal there), which puts the pad
on the surface where the pad normal is along ``-n``. The solve lets it turn up to
``solver.normal_cone_deg`` away, and a pad turned by theta stands up to ``depth (1 - cos theta)``
off the surface (a pad 11.5 mm from its tip frame at 28 degrees: 1.4 mm). A finger's *gap* here is
the least distance of its pad link's collision surface (``POINTS`` points per shape and the
vertices, placed by the kinematics) from the object's surface; a link listed as touching must lie
within :data:`SEATED_M` of it.

:func:`seat_pads`: where a finger's gap is larger, its contact is moved into the object along
``-n`` by the gap (plus ``AIM_M``), its tip moved as much by its own joints, and the problem of the
moved contacts solved again from there (a warm start: the solver's own landing, its tolerance and
FCL check), at most ``ROUNDS`` times; the result's tips then sit that much lower and the pad links
on the surface. (The solve's own link model, spheres around each link, stands out of a fingertip
mesh, so that its collision term alone holds a pad back from the last millimetre.)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
import torch

from graspnet_torch.collision.surface import surface_distance_within, surface_normals
from graspnet_torch.robot.geometry import link_shapes, surface_points
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver import GraspResult
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["AIM_M", "ROUNDS", "SEATED_M", "move_tips", "pad_gaps", "seat_pads"]

SEATED_M = 1e-3  # m: a pad link within this of the surface touches it
AIM_M = 5e-4  # m: a seated contact is moved this much past the gap
ROUNDS = 2  # warm solves at most
POINTS = 256  # surface points per collision shape of a pad link
MEASURED_M = 5e-3  # m: a gap up to this is measured exactly (beyond: the object's distance grid, within 1 mm)
STEPS = 4  # damped least-squares steps of a tip's move
DAMPING = 1e-4  # m: their damping
TURN_M = 0.05  # m per unit of a pad normal's change, in those steps
EPS = 1e-6  # rad (m for a prismatic joint): the finite differences' step


@lru_cache(maxsize=64)
def _link_points(robot: Robot, link: str) -> np.ndarray:
    """(p, 3) points of ``link``'s collision surface, in its frame."""
    parts = [surface_points(s, s.origin, POINTS, POINTS) for s in link_shapes(robot.urdf) if s.link == link]
    return np.concatenate(parts) if parts else np.zeros((0, 3))


def pad_gaps(robot: Robot, obj: Shape, posture: Posture, links: Sequence[str]) -> np.ndarray:
    """(k,) each of ``links``' least distance (m; negative: how deep) from ``obj``'s surface at
    ``posture``: its collision surface's points (module docstring); exact up to ``MEASURED_M``."""
    body = posture.body[None] if robot.has_body else None
    names, frames = robot.link_frames_of(body, posture.fingers[None], posture.palm_pose[None])
    out = np.full(len(links), np.inf)
    for k, link in enumerate(links):
        local = _link_points(robot, link)
        if len(local) and link in names:
            T = frames[0, names.index(link)]
            out[k] = float(surface_distance_within(obj, local @ T[:3, :3].T + T[:3, 3], MEASURED_M).min())
    return out


def seat_pads(robot: Robot, hand: Robot, obj: Shape, problem: GraspProblem, result: GraspResult,
              solve: Callable[[GraspProblem, Posture], GraspResult],
              remake: Callable[[np.ndarray], GraspProblem]) -> tuple[GraspProblem, GraspResult] | None:
    """A successful precision grasp with every contact finger's pad link within :data:`SEATED_M` of
    ``obj`` (module docstring), or None where it cannot be seated.

    Each off finger's contact moves into the object along ``-n`` by its gap (plus ``AIM_M``), its
    tip along with it (:func:`move_tips`: its joints only, the palm kept), and the problem of the
    moved contacts is solved warm from there, so that the reported trial is the solver's (its
    tolerance and its FCL check); at most ``ROUNDS`` times. ``hand``: the robot whose pads these are
    (a hand on an arm: its carried hand); ``solve(problem, posture)``: a warm solve from the
    posture; ``remake(contacts)``: the problem of contacts (k, 3), world, in ``problem.fingers``' order."""
    rows = [hand.finger_index(f) for f in problem.fingers]
    links = [hand.pads[hand.finger_names[r]].link for r in rows]
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    normals = surface_normals(obj, contacts)
    shift = np.zeros(len(links))
    for round_ in range(ROUNDS + 1):
        posture = trial_posture(robot, result.best)
        gaps = pad_gaps(robot, obj, posture, links)
        off = gaps > SEATED_M
        if not off.any():
            return problem, result
        if round_ == ROUNDS:
            return None
        step = np.where(off, gaps + AIM_M, 0.0)
        shift = shift + step
        moved = move_tips(hand, posture, rows, -step[:, None] * normals)
        problem = remake(contacts - shift[:, None] * normals)
        result = solve(problem, moved)
        if not result.success:
            return None
    return None


def move_tips(hand: Robot, posture: Posture, rows: Sequence[int], moves: np.ndarray) -> Posture:
    """``posture`` with the tips of fingers ``rows`` moved by ``moves`` (k, 3), world, their pads
    turned as little as may be: each finger's joints by damped least squares (``STEPS`` steps,
    within the joint limits) on its tip's position and its pad normal (weighted ``TURN_M`` metres
    per unit of the normal's change), their Jacobians by finite differences; the palm and the other
    fingers kept."""
    R = pose_to_matrix_np(posture.palm_pose.numpy())[:3, :3]
    q = posture.fingers.numpy().copy()
    lower, upper = hand.finger_limits
    names = [hand.finger_names[r] for r in rows]
    links, normals = [hand.fingers[f].chain.tip for f in names], [hand.pads[f].normal for f in names]

    def measure(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joints (B, F, n) -> the tips (B, k, 3) and the pads' normals (B, k, 3), palm frame."""
        Qt = torch.as_tensor(Q)
        order, frames = hand.link_frames_of(None, Qt, torch.zeros(len(Q), 6, dtype=torch.float64))
        turned = [frames[:, order.index(link), :3, :3] @ n for link, n in zip(links, normals, strict=True)]
        return hand.fingertips_palm(Qt).numpy()[:, rows], np.stack(turned, axis=1)

    tips, turned = measure(q[None])
    goal, keep = tips[0] + moves @ R, turned[0]
    for _ in range(STEPS):
        Q = np.repeat(q[None], 1 + q.shape[1], axis=0)
        for j in range(q.shape[1]):
            Q[1 + j, rows, j] += EPS
        tips, turned = measure(Q)
        for k, r in enumerate(rows):
            J = np.concatenate([tips[1:, k] - tips[0, k], TURN_M * (turned[1:, k] - turned[0, k])], axis=1).T / EPS
            e = np.concatenate([goal[k] - tips[0, k], TURN_M * (keep[k] - turned[0, k])])
            q[r] += J.T @ np.linalg.solve(J @ J.T + DAMPING**2 * np.eye(6), e)
        q = np.clip(q, lower, upper)
    return Posture(palm_pose=posture.palm_pose, fingers=torch.as_tensor(q), body=posture.body)
