"""Points against primitive obstacles, batched in torch: signed distances and hit tests.

The obstacles and the object of a problem (or of a batch of problems with the same kinds in the
same order) are grouped by kind (:class:`PrimitiveGroup`); a point p, in an element's frame, is
compared with the element's shape (exact for box, cylinder and sphere; a mesh is its convex
pieces, :mod:`graspnet_torch.collision.convex`):

    box (half-extents h):       d = |p| - h;  sd = |max(d, 0)| + min(max_i d_i, 0)
    cylinder (r, half-height):  d = (|p_xy| - r, |p_z| - h);  same formula in 2-D
    sphere (r):                 sd = |p| - r
    convex piece (planes):      sd = max_f (n_f . p - o_f)  (a lower bound outside)
    the floor (a half-space):   sd = p_z - top

A sphere (c, rho) meets an element grown by a margin m when sd(c) < rho - m =: thr; the tests
take thr^2 and compare |max(d, 0)|^2 (no square root), inside always hitting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.convex import FAR, convex_pieces, pieces_distance
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import rpy_to_matrix_np

__all__ = ["GroupThresholds", "PrimitiveGroup", "group_thresholds", "primitive_groups"]

KINDS = ("box", "cylinder", "sphere", "convex", "plane")


@dataclass
class PrimitiveGroup:
    """The elements of one kind of a problem (or of a batch of P problems), stacked.

    Attributes:
        kind: 'box' | 'cylinder' | 'sphere' | 'convex' (a mesh's convex piece) | 'plane' (the floor).
        index: each column's element (its index among the problem's obstacles, floor and object);
            the convex pieces of one mesh share their element.
        R: (P, O, 3, 3) rotations, t: (P, O, 3) origins of the elements in the world.
        size: (P, O, s) half sizes: box (3,) half extents; cylinder (r, half height); sphere (r,);
            plane (0,); convex (P, O, F, 4): the piece's planes (n, o), padded.
        centre: (P, O, 3) a convex piece's bounding-sphere centre in its frame, radius (P, O);
            None for other kinds.
        top: the floor's top (z, world) for 'plane', else 0.
        columns: (O,) ``index`` as a tensor; R_cols: (P, 3, 3 O) [R_1 .. R_O]; Rt: (P, 3 O) [R_o^T t_o].
    """

    kind: str
    index: list[int]
    R: Tensor
    t: Tensor
    size: Tensor
    columns: Tensor
    R_cols: Tensor
    Rt: Tensor
    centre: Tensor | None = None
    radius: Tensor | None = None
    top: float = 0.0

    def local(self, points: Tensor, pid: Tensor | None = None) -> Tensor:
        """(..., T, K, 3) world points -> (..., T, K, O, 3) in each element's frame: R_o^T (x - t_o)
        for every element at once as x @ [R_1 .. R_O] - [R_o^T t_o]; ``pid`` (T,) each trial's
        problem of a batch (None: the first). The floor (a half-space) needs only the height
        above its top: (..., T, K, 1, 1)."""
        if self.kind == "plane":
            return (points[..., 2:3] - self.top).unsqueeze(-2)  # the floor's top: one height for every problem
        if pid is None:
            return (points @ self.R_cols[0] - self.Rt[0]).view(*points.shape[:-1], -1, 3)
        return (points @ self.R_cols[pid] - self.Rt[pid].unsqueeze(-2)).view(*points.shape[:-1], -1, 3)

    def excess(self, p: Tensor, size: Tensor | None = None) -> Tensor:
        """Points p (..., O, 3) in their element's frame -> d (..., O, k): box |p| - h (k = 3);
        cylinder (|p_xy| - r, |p_z| - h) (k = 2); sphere |p| - r, a convex piece max_f (n_f . p -
        o_f), the floor p (k = 1). ``size``: the elements' sizes broadcast against p (None: the
        first problem's)."""
        if self.kind == "plane":
            return p
        size = self.size[0] if size is None else size
        if self.kind == "sphere":
            return (torch.linalg.vector_norm(p, dim=-1) - size[..., 0]).unsqueeze(-1)
        if self.kind == "convex":  # max over the piece's planes: (..., O, 3) against (..., O, F, 4)

            return pieces_distance(p, size).unsqueeze(-1)
        if self.kind == "box":
            return p.abs() - size
        return torch.stack([torch.linalg.vector_norm(p[..., :2], dim=-1), p[..., 2].abs()], dim=-1) - size

    def signed_distance(self, p: Tensor, size: Tensor | None = None) -> Tensor:
        """(..., O, 3) points in their element's frame -> (..., O) signed distances sd =
        |max(d, 0)| + min(max_i d_i, 0) (d: :meth:`excess`)."""
        d = self.excess(p, size)
        return torch.linalg.vector_norm(d.clamp(min=0), dim=-1) + d.amax(-1).clamp(max=0)

    def hits(self, p: Tensor, positive: Tensor, thr_sq: Tensor, size: Tensor | None = None) -> Tensor:
        """sd(p) < thr for points p (..., O, 3) in their element's frame, with thr > 0
        (``positive``; otherwise never) and ``thr_sq`` = thr^2: outside an element |max(d, 0)|^2 <
        thr^2, inside always -> (..., O) bool."""
        d = self.excess(p, size)
        outside = d.clamp(min=0).square().sum(-1)
        return positive & ((outside < thr_sq) | (d.amax(-1) <= 0))


@dataclass
class GroupThresholds:
    """The tests of a robot's sphere clusters (C clusters of K spheres) against a group's O elements.

    Attributes:
        pos: (C, K, O) whether a sphere is tested (thr > 0); thr_sq: (C, K, O) thr^2.
        bound_pos, bound_thr_sq: (C, 1, O) the same for the clusters' bounding spheres (broad phase).
        bound_r: (C, O) for a convex group, the bounding sphere's radius less the margin (the
            piece's radius is added per problem); None for other kinds.
    """

    pos: Tensor
    thr_sq: Tensor
    bound_pos: Tensor
    bound_thr_sq: Tensor
    bound_r: Tensor | None = None


def group_thresholds(group: PrimitiveGroup, radii: np.ndarray, bound_r: np.ndarray, margin: list[float],
                     exempt: np.ndarray, kw: dict) -> GroupThresholds:
    """A sphere (c, rho) hits element o when sd_o(c) < rho - margin_o: radii (C, K) (NaN:
    padding, never hits), bound_r (C,) the clusters' bounding radii, margin: per element of the
    problem, exempt (C, n_elements) clusters never tested against an element."""
    m = np.array([margin[k] for k in group.index])
    thr = radii[:, :, None] - m  # (C, K, O)
    for col, k in enumerate(group.index):
        thr[exempt[:, k], :, col] = -np.inf
    thr = np.nan_to_num(thr, nan=-np.inf)
    pos = torch.as_tensor(thr > 0, device=kw["device"])
    thr_sq = torch.as_tensor(np.where(thr > 0, thr, 0.0) ** 2, **kw)
    # broad phase: the cluster's bounding sphere within reach (of a convex piece's bounding sphere)
    C = len(bound_r)
    bthr = np.broadcast_to(bound_r[:, None, None] - m, (C, 1, len(group.index)))[:, 0]  # (C, O)
    convex_r = None
    if group.kind == "convex":
        convex_r = torch.as_tensor(np.array(bthr), **kw)  # (C, O): + the piece's radius, per problem
        bthr = bthr + group.radius.amax(0).cpu().numpy()[None]
    bound_pos = (torch.as_tensor(bthr > 0, device=kw["device"]) & pos.any(1)).unsqueeze(1)  # (C, 1, O)
    bound_thr_sq = torch.as_tensor(np.where(bthr > 0, bthr, 0.0) ** 2, **kw).unsqueeze(1)
    return GroupThresholds(pos, thr_sq, bound_pos, bound_thr_sq, convex_r)


def primitive_groups(batch: list[list[Shape]], kw: dict, floor: int | None = None) -> list[PrimitiveGroup]:
    """Elements grouped by kind, stacked over the problems of a batch (the same kinds in the same
    order in each), in the order of ``KINDS``. A mesh is its convex pieces
    (:func:`~graspnet_torch.collision.convex.convex_pieces`), one entry of kind ``convex`` each,
    in the mesh's frame; a problem whose mesh has fewer pieces is padded with pieces that never
    hit. Element ``floor`` (the robot's floor slab, the same in every problem) becomes a
    half-space, kind ``plane``: only a height is compared."""
    groups: dict[str, dict] = {}
    slots: dict[tuple[int, int], int] = {}  # (element, piece) -> the convex group's entry
    for p, elements in enumerate(batch):
        for k, e in enumerate(elements):
            R, t = rpy_to_matrix_np(e.pose[3:]), np.asarray(e.pose[:3], dtype=np.float64)
            if e.kind == "mesh":
                pieces = convex_pieces(e.mesh, e.scale)
                entries = [("convex", pieces.planes[j], pieces.centres[j], pieces.radii[j])
                           for j in range(pieces.n_pieces)]
            elif k == floor:
                entries = [("plane", np.zeros(3), None, None)]
                t = t + R @ np.array([0.0, 0.0, e.size[2] / 2])  # the slab's top
            elif e.kind == "box":
                entries = [("box", np.asarray(e.size) / 2, None, None)]
            elif e.kind == "cylinder":
                entries = [("cylinder", np.array([e.size[0], e.size[1] / 2, 0.0]), None, None)]
            else:
                entries = [("sphere", np.array([e.size[0], 0.0, 0.0]), None, None)]
            for j, (kind, size, centre, radius) in enumerate(entries):
                g = groups.setdefault(kind, {"index": [], "R": [], "t": [], "size": [], "centre": [], "radius": []})
                if (k, j) not in slots:
                    slots[k, j] = len(g["index"])
                    g["index"].append(k)
                    for key in ("R", "t", "size", "centre", "radius"):
                        g[key].append({})
                col = slots[k, j]
                g["R"][col][p], g["t"][col][p], g["size"][col][p] = R, t, size
                g["centre"][col][p], g["radius"][col][p] = centre, radius
    out = []
    P = len(batch)
    for kind in KINDS:
        if kind not in groups:
            continue
        g = groups[kind]
        centre = radius = None
        if kind == "convex":  # pad to one face count; a piece a problem lacks never hits
            F = max(s.shape[0] for col in g["size"] for s in col.values())
            never = np.zeros((F, 4))
            never[:, 3] = -FAR
            size = np.stack([np.stack([_pad_planes(col.get(p), F, never) for col in g["size"]]) for p in range(P)])
            first = [next(iter(col.values())) for col in g["R"]]
            R = np.stack([np.stack([col.get(p, first[c]) for c, col in enumerate(g["R"])]) for p in range(P)])
            t = np.stack([np.stack([col.get(p, np.zeros(3)) for col in g["t"]]) for p in range(P)])
            centre = np.stack([np.stack([col.get(p, np.zeros(3)) for col in g["centre"]]) for p in range(P)])
            radius = np.stack([np.array([col.get(p, 0.0) for col in g["radius"]]) for p in range(P)])
            centre, radius = torch.as_tensor(centre, **kw), torch.as_tensor(radius, **kw)
        else:
            s = {"box": 3, "plane": 1}.get(kind, 2)
            size = np.stack([np.stack([col[p][:s] for col in g["size"]]) for p in range(P)])
            R = np.stack([np.stack([col[p] for col in g["R"]]) for p in range(P)])
            t = np.stack([np.stack([col[p] for col in g["t"]]) for p in range(P)])
        Rw, tw = torch.as_tensor(R, **kw), torch.as_tensor(t, **kw)
        out.append(PrimitiveGroup(
            kind=kind, index=g["index"], R=Rw, t=tw, size=torch.as_tensor(size, **kw),
            columns=torch.as_tensor(g["index"], device=kw["device"]),
            R_cols=Rw.permute(0, 2, 1, 3).reshape(P, 3, -1),  # per problem [R_1 .. R_O]
            Rt=torch.einsum("poji,poj->poi", Rw, tw).reshape(P, -1),  # per problem [R_o^T t_o]
            centre=centre, radius=radius, top=float(t[0, 0, 2]) if kind == "plane" else 0.0))
    return out


def _pad_planes(planes: np.ndarray | None, F: int, never: np.ndarray) -> np.ndarray:
    """(F, 4): a piece's planes padded with planes that are never the largest; a missing piece
    (None): ``never``, planes that put every point far outside."""
    if planes is None:
        return never
    out = np.zeros((F, 4))
    out[:, 3] = FAR
    out[: len(planes)] = planes
    return out
