"""A mesh link as spheres that hug it: the collision proxy's model of a mesh.

A mesh's bounding box is a poor model of a rounded or tapered link (a fingertip's hemisphere, a
motor housing narrowing into a rod): the box's spheres stand out of the link by a third of its
thickness (TriFinger's: up to 35 mm), so a pad touching an object already "penetrates" it and two
fingers side by side "overlap". This module covers the mesh with spheres within a *slack* of it
either way: ``SLACK`` times the mesh's thickness (its points' extent along their least principal
axis), at least ``SLACK_MIN_M``:

1. *Points*: the mesh's vertices and ``SAMPLES`` points drawn evenly over its surface (seeded:
   the same mesh gives the same spheres).
2. *Slabs*: the points are cut into slabs across their longest principal axis, each about as long
   as the mesh is wide (overlapping by the slack), and each slab's convex hull is taken (at most
   ``POINTS_PER_SLAB`` points, evenly thinned): a tapered or bent link is followed slab by slab.
3. *Candidates*: centres on a grid inside each hull (``GRID`` across it), and below each point
   along its nearest hull plane's normal at ``DEPTHS`` of the slab's largest inscribed radius,
   each with the radius of the largest sphere inscribed in the hull there plus the slack; and the
   points themselves, radius the slack.
4. *Cover*: greedy set cover picks, slab by slab, the candidate holding the most points not yet
   covered until every point is covered.

So no sphere stands out of its slab's hull by more than the slack, and every point lies in a
sphere; the surface between the points lies within the slack of one (measured on a box and on
TriFinger's links: within 0.9 of the slack, tests/collision/test_mesh_links.py). A concave link is
modelled by its slabs' hulls: TriFinger's middle link stands out of its mesh by up to 20 mm (35 mm
as a box). Made once per (file, scale) in a process.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from graspnet_torch.meshes import sample_even

__all__ = ["SAMPLES", "SLACK", "SLACK_MIN_M", "mesh_key", "mesh_spheres"]

SAMPLES = 3000  # surface points per mesh (besides its vertices)
SLACK = 0.08  # how far the spheres may stand out of the slab hulls, as a share of the box's smallest extent
SLACK_MIN_M = 5e-4  # ... and at least this (m)
DEPTHS = (0.25, 0.5, 1.0)  # candidates below each point, as shares of the slab's largest inscribed radius
GRID = 5  # candidate centres per slab across its width (and as many per width along it)
POINTS_PER_SLAB = 1500  # points covered per slab at most (evenly thinned): bounds the cover's cost


def mesh_spheres(mesh, key: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Spheres covering ``mesh`` (a ``trimesh.Trimesh``, in its own frame): centres (k, 3) and radii
    (k,) (module docstring). ``key``: a hashable name of the mesh (:func:`mesh_key`): the spheres
    are computed once per key in a process (None: every call)."""
    found = _CACHE.get(key) if key is not None else None
    if found is None:
        found = _spheres(np.asarray(mesh.vertices, dtype=np.float64), sample_even(mesh, SAMPLES))
        if key is not None:
            _CACHE[key] = found
    return found[0].copy(), found[1].copy()


_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def _spheres(vertices: np.ndarray, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cover of the points ``vertices`` (V, 3) and ``samples`` (S, 3) (module docstring)."""
    from scipy.spatial import ConvexHull, QhullError

    points = np.unique(np.vstack([vertices, samples]).round(9), axis=0)
    centre = points.mean(axis=0)
    axes = np.linalg.svd(points - centre, full_matrices=False)[2]  # rows: principal axes, longest first
    local = (points - centre) @ axes.T
    lo, hi = local.min(axis=0), local.max(axis=0)
    extent = hi - lo
    slack = max(SLACK_MIN_M, SLACK * float(extent.min()))
    width = max(float(extent[1]), 4 * slack)
    n_slabs = max(1, math.ceil(float(extent[0]) / width))
    edges = np.linspace(lo[0], hi[0], n_slabs + 1)
    out_c: list[np.ndarray] = []
    out_r: list[np.ndarray] = []
    for k in range(n_slabs):
        inside = (local[:, 0] >= edges[k] - slack) & (local[:, 0] <= edges[k + 1] + slack)
        pts = local[inside]
        if len(pts) > POINTS_PER_SLAB:
            pts = pts[np.linspace(0, len(pts) - 1, POINTS_PER_SLAB).astype(int)]
        try:
            planes = ConvexHull(pts).equations  # (P, 4): n . x + d <= 0 inside
        except (QhullError, ValueError):  # flat or too few points: the points themselves
            planes = None
        cands, rads = pts, np.zeros(len(pts))
        if planes is not None:
            cands, rads = _candidates(pts, planes, slack)
        c, r = _cover(cands, rads + slack, pts)
        out_c.append(c)
        out_r.append(r)
    centres = np.vstack(out_c) @ axes + centre
    return centres, np.concatenate(out_r)


def _candidates(pts: np.ndarray, planes: np.ndarray, slack: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres (C, 3) and their inscribed radii (C,) in a slab's hull (``planes`` (P, 4),
    n . x + d <= 0 inside): a grid over it, and below each point along the normal of its nearest
    plane at ``DEPTHS`` of the largest inscribed radius (a sphere tangent there covers a disc
    about the point); the points themselves last (radius 0: each covers itself)."""
    a, b = pts.min(axis=0), pts.max(axis=0)
    step = max(float((b - a)[1:].max()) / GRID, slack)
    grid = np.stack(np.meshgrid(*[np.arange(a[i] + step / 2, b[i], step) for i in range(3)],
                                indexing="ij"), -1).reshape(-1, 3)
    grid = np.vstack([grid, pts.mean(axis=0, keepdims=True)])
    depth = -(grid @ planes[:, :3].T + planes[:, 3]).max(axis=1)
    deepest = max(float(depth.max()), slack)
    normal = planes[np.argmax(pts @ planes[:, :3].T + planes[:, 3], axis=1), :3]  # (N, 3) nearest plane's
    below = np.concatenate([pts - f * deepest * normal for f in DEPTHS])
    cands = np.vstack([grid, below])
    inscribed = -(cands @ planes[:, :3].T + planes[:, 3]).max(axis=1)
    keep = inscribed > 0
    return np.vstack([cands[keep], pts]), np.concatenate([inscribed[keep], np.zeros(len(pts))])


def _cover(cands: np.ndarray, radii: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Greedy set cover: spheres (cands (C, 3), radii (C,)) picked until every point (P, 3) lies in
    one, each time the one holding the most points not yet covered (ties: the larger)."""
    sq = (cands * cands).sum(1)[:, None] - 2 * cands @ points.T + (points * points).sum(1)[None, :]
    holds = sq <= np.square(radii)[:, None] + 1e-12  # (C, P)
    gain = holds.sum(axis=1).astype(np.float64) + radii * 1e-3  # ties: the larger
    left = np.ones(len(points), dtype=bool)
    picked: list[int] = []
    while left.any():
        best = int(np.argmax(gain))
        picked.append(best)
        newly = holds[best] & left
        left &= ~newly
        gain -= holds[:, newly].sum(axis=1)
    return cands[picked], radii[picked]


def mesh_key(path: Path | str | None, scale) -> tuple | None:
    """The cache key of a mesh file at a scale (None where there is no file)."""
    if path is None:
        return None
    return (str(path), tuple(np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)).tolist()))
