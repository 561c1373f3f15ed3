"""Fingers closed onto an object along straight lines in joint space, each until its pad touches
(the sampler of :mod:`graspnet_torch.synthesis.drafts`, step 2 of its docstring): the lines
(:func:`closing_lines`: from the pad's forward direction, :func:`tip_jacobians`) and where along
them each pad sphere first touches the surface (:func:`close_lines`, on the object's fast distance
:func:`~graspnet_torch.collision.surface.surface_distance_near`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from graspnet_torch.collision.surface import surface_distance_near
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_rt

__all__ = ["BISECT", "CLOSE", "FORWARD", "HOLD", "OPEN", "STEPS", "close_lines", "closing_lines", "pad_forward",
           "tip_jacobians"]

STEPS = 24  # samples of each finger's closing line
BISECT = 14  # bisection steps after the first sample that touches
OPEN = (0.0, 0.3)  # a finger's open posture: this fraction of each joint's range above its lower limit
CLOSE = (0.45, 1.0)  # its closed posture
FORWARD = 0.3  # a joint turns a pad "forward" when its tip motion's cosine to the pad normal is at least this
HOLD = (0.35, 0.65)  # a joint that turns its pad sideways: held at this fraction of its range


def _tip_gaps(robot: Robot, obj: Shape, R: torch.Tensor, t: torch.Tensor, q: torch.Tensor, depth: np.ndarray,
              rows: list[int]) -> np.ndarray:
    """Signed gaps (m) of the pad spheres of the fingers ``rows`` to the surface: the palm's pose
    R (..., 3, 3), t (..., 3) (:func:`pose_to_rt`), q (..., F, j) -> (..., len(rows))."""
    palm = robot.some_fingertips_palm(q, rows)
    # R @ p + t as an einsum: the same values as transform_points' matmul, which would copy R for every tip
    tips = (torch.einsum("...ij,...j->...i", R.unsqueeze(-3), palm) + t.unsqueeze(-2)).numpy()
    return surface_distance_near(obj, tips.reshape(-1, 3)).reshape(tips.shape[:-1]) - depth[rows]


def close_lines(robot: Robot, obj: Shape, head: torch.Tensor, q_open: torch.Tensor, q_close: torch.Tensor,
                depth: np.ndarray, rows: Sequence[int] | None = None) -> tuple[torch.Tensor, np.ndarray]:
    """Each finger of ``rows`` (None: every finger) closed along its line until its pad touches.
    head (B, 6), q_open / q_close (B, F, j) -> the touching joints (B, F, j) (closed where it
    touches nothing; a finger not in ``rows``: closed, not measured), touched (B, F) bool (False
    for a finger not in ``rows``)."""
    B, F = q_open.shape[:2]
    rows = list(range(F)) if rows is None else list(rows)
    ts = torch.linspace(0, 1, STEPS, dtype=torch.float64)
    line = q_open[:, None] + ts[None, :, None, None] * (q_close - q_open)[:, None]  # (B, S, F, j)
    R, at = pose_to_rt(head)  # the palm's pose, once per line
    gaps = _tip_gaps(robot, obj, R[:, None], at[:, None], line, depth, rows)  # (B, S, k)
    inside = gaps <= 0
    touched = np.zeros((B, F), dtype=bool)
    touched[:, rows] = inside.any(axis=1) & ~inside[:, 0]
    t = torch.ones(B, F, dtype=torch.float64)
    first = np.where(touched[:, rows], inside.argmax(axis=1), STEPS - 1)  # (B, k)
    lo_t = torch.as_tensor(np.where(touched[:, rows], (first - 1) / (STEPS - 1), 1.0))
    hi_t = torch.as_tensor(first / (STEPS - 1))
    for _ in range(BISECT):  # the pad on the surface: gap(lo) > 0 >= gap(hi)
        t[:, rows] = (lo_t + hi_t) / 2
        gap = _tip_gaps(robot, obj, R, at, q_open + t[..., None] * (q_close - q_open), depth, rows)
        above = torch.as_tensor(gap > 0)
        lo_t, hi_t = torch.where(above, t[:, rows], lo_t), torch.where(above, hi_t, t[:, rows])
    t[:, rows] = torch.where(torch.as_tensor(touched[:, rows]), hi_t, torch.ones_like(hi_t))  # the others: 1
    return q_open + t[..., None] * (q_close - q_open), touched


def pad_forward(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N, F, n) how much each joint's increase moves its finger's pad sphere forward, along the
    pad normal: the tip's Jacobian column (:func:`tip_jacobians`) dotted with the tip-frame pad normal,
    over the column's length (a cosine; 0 for padding or a joint that does not move the tip); palm
    frame, q (N, F, n). A finger without a pad: normal +y of its tip frame."""
    N = q.shape[0]
    normal = np.stack([robot.pads[f].normal if f in robot.pads else np.array([0.0, 1.0, 0.0]) for f in robot.fingers])
    names, frames = robot.link_frames_of(None, torch.as_tensor(q), torch.zeros(N, 6, dtype=torch.float64))
    R = frames[:, [names.index(robot.cfg.fingers[f].tip) for f in robot.fingers], :3, :3]  # (N, F, 3, 3)
    forward = np.einsum("nfij,fj->nfi", R, normal)
    J = tip_jacobians(robot, q)
    length = np.linalg.norm(J, axis=-2)
    return np.einsum("nfi,nfij->nfj", forward, J) / np.maximum(length, 1e-9) * (length > 1e-9)


def tip_jacobians(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N, F, 3, n) every finger's tip Jacobian in the palm frame at joints q (N, F, n): the finger
    kernel's analytic one (:meth:`Robot.fingertips_base_jacobian`, each finger's base frame) turned
    into the palm frame (each column as the move of a point, :meth:`Robot.base_to_palm`)."""
    p, J = robot.fingertips_base_jacobian(torch.as_tensor(q))  # (N, F, 3), (N, F, 3, n)
    at = robot.base_to_palm(p)
    return torch.stack([robot.base_to_palm(p + J[..., j]) - at for j in range(J.shape[-1])], dim=-1).numpy()


def closing_lines(robot: Robot, lo: np.ndarray, span: np.ndarray, rng: np.random.Generator, N: int
           ) -> tuple[torch.Tensor, torch.Tensor]:
    """N closing lines of every finger (module docstring, step 2): open and closed joints (N, F, n).

    Each joint's direction comes from the pad: at the unturned open posture (``OPEN`` fractions
    above the lower limits) a joint whose increase moves the pad forward (cosine ``pad_forward`` at
    least ``FORWARD``) goes from ``OPEN`` up to ``CLOSE`` (fractions of its range above its lower
    limit), one whose increase moves it back (at most ``-FORWARD``) the mirror image (the fractions
    below its upper limit), and one that moves it sideways is held (``HOLD``)."""
    u_open, u_close = rng.uniform(*OPEN, (N, *lo.shape)), rng.uniform(*CLOSE, (N, *lo.shape))
    u_hold = rng.uniform(*HOLD, (N, *lo.shape))
    cos = pad_forward(robot, lo + u_open * span)
    up, down = cos >= FORWARD, cos <= -FORWARD
    hold = lo + u_hold * span
    q_open = np.where(up, lo + u_open * span, np.where(down, lo + (1 - u_open) * span, hold))
    q_close = np.where(up, lo + u_close * span, np.where(down, lo + (1 - u_close) * span, hold))
    return torch.as_tensor(q_open), torch.as_tensor(q_close)
