"""The robot's own links against each other, batched in torch, for the loop's collision proxy.

The links of ``self_collision: true`` are capsules (a segment and a radius: spheres, cylinders,
small boxes; :func:`self_collision_primitive`) and boxes (the rest), tested pair by pair for
every configuration at once:

    capsule-capsule:  |closest points of the two segments| < r_1 + r_2 + clearance  (exact)
    capsule-box:      the segment meets the box grown by r + clearance (slab test; conservative
                      by up to (sqrt(3) - 1) r at the box's corners)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.spheres import cylinder_axis_half, mesh_box
from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.frames import Attachment
from graspnet_torch.robot.geometry import LinkShape

__all__ = ["SMALL_BOX_M", "SelfCollisionModel", "segment_distance_sq", "segment_meets_box",
           "self_collision_primitive"]

SMALL_BOX_M = 0.1  # boxes whose longest half-extent is at most this are capsules for self-collision


def self_collision_primitive(shape: LinkShape) -> tuple[str, np.ndarray, np.ndarray | float]:
    """A link primitive for the self-collision test, in its link's frame: ``("capsule", ends (2, 3),
    radius)`` or ``("box", pose (4, 4), half extents (3,))``. A sphere is a capsule of length 0; a
    cylinder (r, L) the capsule of radius r whose segment runs along its axis to (L/2 - e) of each
    end, e = min(r/4, L/2) (it overshoots the flat ends by 3r/4 on the axis, where the URDF's joints
    sit); a small box (longest half-extent <= ``SMALL_BOX_M``: a gripper, its jaws) the capsule
    along its longest axis with the half-diagonal of its cross-section as radius (it bulges by
    up to that radius beyond the box); any other box is itself; a mesh is its box (:func:`mesh_box`)."""
    shape = mesh_box(shape)
    R, t = shape.origin[:3, :3], shape.origin[:3, 3]
    if shape.kind == "sphere":
        return "capsule", np.stack([t, t]), float(shape.size[0])
    if shape.kind == "cylinder":
        r, length = shape.size
        half = cylinder_axis_half(r, length)
        return "capsule", np.stack([t - half * R[:, 2], t + half * R[:, 2]]), float(r)
    if shape.kind == "box":
        h = np.asarray(shape.size, dtype=np.float64) / 2
        if h.max() > SMALL_BOX_M:
            return "box", shape.origin.copy(), h
        k = int(np.argmax(h))
        radius = float(np.sqrt(np.sum(np.delete(h, k) ** 2)))
        return "capsule", np.stack([t - h[k] * R[:, k], t + h[k] * R[:, k]]), radius
    raise ConfigError(f"link '{shape.link}': no self-collision model for {shape.kind}")  # pragma: no cover


def segment_distance_sq(p1: Tensor, q1: Tensor, p2: Tensor, q2: Tensor, eps: float = 1e-12) -> Tensor:
    """Squared distance between segments [p1, q1] and [p2, q2], all (..., 3) -> (...): the closest
    points p1 + s d1 and p2 + t d2 (Ericson, Real-Time Collision Detection, 5.1.9):

        s = clamp((b f - c e) / (a e - b^2)),  t = (b s + f) / e;  t < 0: t = 0, s = clamp(-c / a);
        t > 1: t = 1, s = clamp((b - c) / a)
        a = d1.d1, b = d1.d2, c = d1.r, e = d2.d2, f = d2.r, r = p1 - p2, clamp to [0, 1];

    a point (a or e ~ 0) takes the point-segment branch."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = (d1 * d1).sum(-1), (d2 * d2).sum(-1)
    b, c, f = (d1 * d2).sum(-1), (d1 * r).sum(-1), (d2 * r).sum(-1)
    a_, e_ = a.clamp(min=eps), e.clamp(min=eps)
    denom = a * e - b * b
    s = torch.where(denom > eps, ((b * f - c * e) / denom.clamp(min=eps)).clamp(0, 1), torch.zeros_like(a))
    t = (b * s + f) / e_
    s = torch.where(t < 0, (-c / a_).clamp(0, 1), torch.where(t > 1, ((b - c) / a_).clamp(0, 1), s))
    t = t.clamp(0, 1)
    s = torch.where(e <= eps, (-c / a_).clamp(0, 1), s)  # the second is a point
    t = torch.where(e <= eps, torch.zeros_like(t), t)
    s = torch.where(a <= eps, torch.zeros_like(s), s)  # the first is a point
    t = torch.where(a <= eps, (f / e_).clamp(0, 1), t)
    return (r + d1 * s.unsqueeze(-1) - d2 * t.unsqueeze(-1)).square().sum(-1)


def segment_meets_box(p0: Tensor, p1: Tensor, half: Tensor) -> Tensor:
    """Whether segments [p0, p1] (..., 3), in a box's frame, meet the box |x_i| <= half_i (..., 3):
    the slab test, t in [0, 1] within every slab -h_i <= p0_i + t (p1_i - p0_i) <= h_i."""
    d = p1 - p0
    d = torch.where(d.abs() < 1e-12, torch.full_like(d, 1e-12), d)  # parallel to a slab: +-inf-like bounds
    lo, hi = (-half - p0) / d, (half - p0) / d
    enter = torch.minimum(lo, hi).amax(-1).clamp(min=0)
    leave = torch.maximum(lo, hi).amin(-1).clamp(max=1)
    return enter <= leave


class SelfCollisionModel:
    """Tensors of the self-collision test of some link pairs: capsules (ends in their frame,
    radius), boxes (pose in their frame, half extents), and the primitive pairs of each link
    pair: capsule-capsule (exact: segment distance) and capsule-box (the segment against the box
    grown by the radius: conservative by up to (sqrt(3) - 1) r at the box's corners). A pair of
    two boxes has no test here: it is left to FCL (``unchecked``).

    Args:
        shapes: the robot's collision shapes; those of links in no pair are left out.
        pairs: the link pairs to test.
        attachments: each link's level frame and pose in it; ``frame_id`` numbers the frames as
            :meth:`hits` receives them.
        clearance: pairs count as colliding from this distance on (m).
    """

    def __init__(self, shapes: list[LinkShape], pairs: list[tuple[str, str]], attachments: dict[str, Attachment],
                 frame_id: Callable[[Attachment], int], clearance: float, kw: dict):
        device = kw["device"]
        self.pairs = pairs
        involved = set(link for pair in pairs for link in pair)
        caps, boxes = [], []  # (link, frame id, ...)
        for shape in shapes:
            if shape.link not in involved:
                continue
            where = attachments[shape.link]
            G = where.pose
            kind, a, b = self_collision_primitive(shape)
            if kind == "capsule":
                ends = G[:3, :3] @ a.T + G[:3, 3:4]  # (3, 2)
                caps.append((shape.link, frame_id(where), ends, float(b)))
            else:
                boxes.append((shape.link, frame_id(where), G @ a, b))
        cc, cb, unchecked = [], [], []  # (i, j, link pair) index triples
        for p, (la, lb) in enumerate(pairs):
            ca = [i for i, c in enumerate(caps) if c[0] == la]
            cb_ = [i for i, c in enumerate(caps) if c[0] == lb]
            ba = [i for i, x in enumerate(boxes) if x[0] == la]
            bb = [i for i, x in enumerate(boxes) if x[0] == lb]
            cc += [(i, j, p) for i in ca for j in cb_]
            cb += [(i, j, p) for i in ca for j in bb] + [(i, j, p) for i in cb_ for j in ba]
            if ba and bb:
                unchecked.append(p)
        ends = np.zeros((len(caps), 4, 2))
        for k, (_l, _f, e, _r) in enumerate(caps):
            ends[k, :3], ends[k, 3] = e, 1.0
        radius = np.array([c[3] for c in caps])
        self._cap_frame = torch.tensor([c[1] for c in caps], dtype=torch.long, device=device)
        self._cap_ends = torch.as_tensor(ends, **kw)  # (N_cap, 4, 2): homogeneous end points
        self._box_frame = torch.tensor([x[1] for x in boxes], dtype=torch.long, device=device)
        self._box_pose = torch.as_tensor(np.stack([x[2] for x in boxes]) if boxes else np.zeros((0, 4, 4)), **kw)
        n_pairs = len(pairs)

        def index(rows: list[tuple[int, int, int]], col: int) -> Tensor:
            return torch.tensor([r[col] for r in rows], dtype=torch.long, device=device)

        self._cc_i, self._cc_j = index(cc, 0), index(cc, 1)
        self._cc_thr_sq = torch.as_tensor([(radius[i] + radius[j] + clearance) ** 2 for i, j, _p in cc], **kw)
        self._cb_cap, self._cb_box = index(cb, 0), index(cb, 1)
        grow = [boxes[j][3] + radius[i] + clearance for i, j, _p in cb]
        self._cb_grow = torch.as_tensor(np.array(grow).reshape(-1, 3), **kw)  # (N_cb, 3): grown half extents
        # (N, P) which link pair each primitive pair belongs to: hits (T, N) @ it > 0 -> (T, P)
        self._cc_pair = torch.zeros(len(cc), n_pairs, **kw)
        self._cc_pair[torch.arange(len(cc)), index(cc, 2)] = 1
        self._cb_pair = torch.zeros(len(cb), n_pairs, **kw)
        self._cb_pair[torch.arange(len(cb)), index(cb, 2)] = 1
        self.unchecked = [pairs[p] for p in unchecked]
        self.tested = bool(len(cc) or len(cb))

    def drop(self, pairs: Tensor) -> None:
        """Stop testing the link pairs where ``pairs`` (P,) bool is True (they join ``unchecked``)."""
        keep = (~pairs).to(self._cc_pair.dtype)
        self._cc_pair, self._cb_pair = self._cc_pair * keep, self._cb_pair * keep
        self.unchecked += [pair for pair, t in zip(self.pairs, pairs.tolist(), strict=True) if t]

    def hits(self, frames: Tensor) -> Tensor:
        """Every frame (n_frames, T, 3, 4) -> (T, P) bool: pair p collides (with the clearance)."""
        T = frames.shape[1]
        n = len(self._cap_frame)
        ends = torch.bmm(frames[self._cap_frame].reshape(n, T * 3, 4), self._cap_ends).view(n, T, 3, 2)
        start, end = ends[..., 0], ends[..., 1]  # (N_cap, T, 3)
        hits = torch.zeros(T, len(self.pairs), dtype=self._cc_pair.dtype, device=frames.device)
        if len(self._cc_i):
            i, j = self._cc_i, self._cc_j
            d2 = segment_distance_sq(start[i], end[i], start[j], end[j])  # (N_cc, T)
            hits = hits + (d2 < self._cc_thr_sq.unsqueeze(1)).to(hits.dtype).T @ self._cc_pair
        if len(self._cb_cap):
            W = frames[self._box_frame]  # (N_box, T, 3, 4) each box's link frame -> its pose
            R = W[..., :3] @ self._box_pose[:, None, :3, :3]
            t = (W[..., :3] @ self._box_pose[:, None, :3, 3:]).squeeze(-1) + W[..., 3]
            Rb, tb = R[self._cb_box], t[self._cb_box]  # (N_cb, T, ...)
            c = self._cb_cap
            p0 = ((start[c] - tb).unsqueeze(-2) @ Rb).squeeze(-2)  # rows: R^T (x - t), in the box frame
            p1 = ((end[c] - tb).unsqueeze(-2) @ Rb).squeeze(-2)
            hit = segment_meets_box(p0, p1, self._cb_grow.unsqueeze(1))  # (N_cb, T)
            hits = hits + hit.to(hits.dtype).T @ self._cb_pair
        return hits > 0
