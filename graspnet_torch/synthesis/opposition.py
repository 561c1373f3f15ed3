"""Opposed pad placements: finger postures whose chosen pads face each other across an object,
and where to put the object's centre (the palm frame) so that each pad meets its surface.

A *bank* of finger postures is drawn once per call (``BANK`` uniform postures between
``RANGE`` of each joint's range), in the palm frame; a posture is kept where the first chosen
finger's pad (the thumb's) faces against the others' mean pad normal (dot below
``-OPPOSE_DOT``) and toward them. For a palm orientation, each banked posture puts the object's
centre where the thumb's line (its touch point, then inward along its normal by the object's
reach toward that pad) meets the other pads' (their mean): halfway, and their spread (half how
far they miss each other, m). The palm's placement takes the banked posture that misses least.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from graspnet_torch.collision.surface import surface_distance
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape

__all__ = ["BANK", "OPPOSE_DOT", "RANGE", "OpposedBank", "opposed_bank", "place"]

BANK = 16384  # finger postures drawn for the bank
RANGE = (0.1, 0.9)  # the bank's postures: this fraction of each joint's range above its lower limit
OPPOSE_DOT = 0.3  # the thumb's pad normal dotted with the others' mean lies below minus this
PICK = 48  # banked postures compared per palm orientation


@dataclass(frozen=True)
class OpposedBank:
    """Opposed finger postures in the palm frame.

    Attributes:
        q: (M, F, j) the finger joints.
        points: (M, k, 3) the chosen pads' touch points (tip + depth along the pad normal).
        normals: (M, k, 3) the chosen pads' unit normals (into the object).
    """

    q: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def opposed_bank(robot: Robot, rows: list[int], depth: np.ndarray, rng: np.random.Generator) -> OpposedBank:
    """The bank of opposed postures for the fingers ``rows`` (module docstring); ``depth`` (F,)
    each finger's pad depth."""
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    q = lo + rng.uniform(*RANGE, (BANK, *lo.shape)) * (hi - lo)
    qt = torch.as_tensor(q)
    head = torch.zeros(BANK, 6, dtype=torch.float64)
    names, frames = robot.link_frames_of(None, qt, head)
    fingers = list(robot.fingers)
    tips = robot.fingertips_palm(qt).numpy()[:, rows]  # (M, k, 3)
    R = frames[:, [names.index(robot.cfg.fingers[fingers[r]].tip) for r in rows], :3, :3]
    pad = np.stack([robot.pads[fingers[r]].normal for r in rows])
    normals = np.einsum("mkij,kj->mki", R, pad)
    points = tips + normals * depth[rows][None, :, None]
    keep = np.ones(BANK, dtype=bool)
    if len(rows) > 1:
        others = normals[:, 1:].mean(axis=1)
        toward = points[:, 1:].mean(axis=1) - points[:, 0]
        keep = (np.einsum("mi,mi->m", normals[:, 0], others) < -OPPOSE_DOT) & \
            (np.einsum("mi,mi->m", normals[:, 0], toward) > 0)
    return OpposedBank(q[keep], points[keep], normals[keep])


def place(bank: OpposedBank, obj: Shape, rng: np.random.Generator, B: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """B palm placements, thumb first: a random surface point, the palm turned (random roll) so a
    banked posture's thumb pad lies on it facing into the object, of ``PICK`` banked postures the
    one whose other pads land nearest the surface. -> palm orientations (B, 3, 3), the object's
    centre in the palm frame (B, 3), the postures' joints (B, F, j), their miss (B,) m (the
    other pads' worst distance to the surface)."""
    mesh = obj.trimesh()
    pts, faces = mesh.sample(B, return_index=True, seed=int(rng.integers(2**31)))
    out = np.asarray(mesh.face_normals[faces], dtype=np.float64)  # (B, 3) outward
    idx = rng.integers(0, len(bank.q), (B, PICK))
    n_t, p_t = bank.normals[idx, 0], bank.points[idx, 0]  # (B, P, 3) palm frame
    F_p = _frame(n_t, rng)
    F_w = _frame(np.broadcast_to(-out[:, None], n_t.shape), rng)
    R = F_w @ np.swapaxes(F_p, -1, -2)  # (B, P, 3, 3): palm -> world
    t = np.asarray(pts)[:, None] - np.einsum("bpij,bpj->bpi", R, p_t)
    others = np.einsum("bpij,bpkj->bpki", R, bank.points[idx, 1:]) + t[:, :, None]
    miss = np.abs(surface_distance(obj, others.reshape(-1, 3))).reshape(others.shape[:-1]).max(axis=-1)
    best = miss.argmin(axis=1)
    b = np.arange(B)
    Rb, tb = R[b, best], t[b, best]
    centre = np.einsum("bji,bj->bi", Rb, np.asarray(obj.pose[:3], dtype=np.float64) - tb)
    return Rb, centre, bank.q[idx[b, best]], miss[b, best]


def _frame(n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Orthonormal frames (..., 3, 3), columns n (unit) and two random perpendiculars."""
    u = np.cross(n, rng.normal(size=n.shape))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return np.stack([n, u, np.cross(n, u)], axis=-1)
