"""Mesh objects and obstacles as FCL sees them: the mesh itself, its inside, and how deep a link goes in.

FCL checks a triangle mesh as a BVH of its triangles: it finds where a link's geometry crosses
the surface, but not a link wholly inside, and its penetration depths against a mesh are those of
single triangles (measured: negative, or the triangle's, not the object's). So for a mesh the
engine of record adds two measurements of its own, against the mesh itself:

- *inside*: a point is inside a closed (watertight) mesh by ray parity (trimesh's ray test along
  one fixed direction, both ways; a point whose rays disagree gets its winding number: the same
  answer every run); a mesh that is not closed has no inside of its own, and its convex pieces
  (:mod:`graspnet_torch.collision.convex`) stand for it;
- *depth* of a link: the largest depth below the surface of points spread over the link's
  geometry (its surface, at most ``SPACING`` apart, and its vertices), i.e. how far the link
  reaches into the object: for the points inside, their distance to the surface
  (:meth:`MeshQuery.distance`: a KD-tree of the finely cut surface, and exact point-triangle
  distances where that bound cannot decide against the tolerance).
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from graspnet_torch.collision.convex import convex_pieces
from graspnet_torch.meshes import load_mesh, mesh_path, sample_even
from graspnet_torch.robot.transforms import pose_to_matrix_np

__all__ = ["MeshQuery", "closest_on_triangles", "closest_points", "closest_points_rows", "lattice_points", "mesh_query",
           "point_triangle_distance", "shape_points"]

SPACING = 0.002  # m between the points that measure a link's depth
MEASURED = 0.01  # m: depths are measured up to this (deeper is reported as this)
CHUNK = 64  # inside points measured at a time
PAIRS = 32768  # (point, triangle) pairs closest_points measures at once (the arrays stay in the cache)
RAY = np.array([0.4395064455, 0.617598629942, 0.652231566745])  # the inside test's ray (trimesh's default)
MAX_POINTS = 1500


def shape_points(kind: str, size: tuple[float, ...], mesh=None) -> np.ndarray:
    """(N, 3) points spread over a shape's surface (at most ``SPACING`` apart, at most
    ``MAX_POINTS``), its vertices included, in the shape's own frame: a box (full extents), a
    cylinder (radius, length along z), a sphere (radius,) or a mesh (a ``trimesh.Trimesh``).
    A primitive's are made once per kind and size (cached, read-only): every collision scene of a
    robot asks for its links' points again."""
    if kind in ("box", "cylinder", "sphere"):
        return _primitive_points(kind, tuple(float(x) for x in size))
    return _surface_points(mesh)


@lru_cache(maxsize=256)
def _primitive_points(kind: str, size: tuple[float, ...]) -> np.ndarray:
    import trimesh

    if kind == "box":
        surface = trimesh.creation.box(extents=size)
    elif kind == "cylinder":
        surface = trimesh.creation.cylinder(radius=size[0], height=size[1], sections=32)
    else:
        surface = trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    points = _surface_points(surface)
    points.flags.writeable = False
    return points


def _surface_points(surface) -> np.ndarray:
    """(N, 3) :func:`shape_points` of a ``trimesh.Trimesh``: its vertices, then an even sample."""
    count = min(MAX_POINTS, max(64, math.ceil(surface.area / SPACING**2)))
    return np.concatenate([np.asarray(surface.vertices, dtype=np.float64), sample_even(surface, count)])


def lattice_points(triangles: np.ndarray, s: float) -> np.ndarray:
    """(N, 3) the vertices of each triangle (M, 3, 3) cut into n^2 copies of itself, n the least
    with every edge over n at most ``s``: the points ``a + (i (b - a) + j (c - a)) / n``, i, j >= 0,
    i + j <= n (an edge's points once per triangle sharing it). Every point of the surface lies
    within s / sqrt(3) of one of them (the circumradius of a triangle of edges at most s, or half its
    longest edge where obtuse)."""
    a, b, c = (triangles[:, k] for k in range(3))
    longest = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                        np.linalg.norm(a - c, axis=1)]).max(axis=0)
    n = np.maximum(1, np.ceil(longest / s - 1e-9)).astype(int)
    out = []
    for m in np.unique(n):
        i, j = (v.ravel() for v in np.meshgrid(np.arange(m + 1), np.arange(m + 1), indexing="ij"))
        keep = i + j <= m
        u, v = i[keep] / m, j[keep] / m  # (P,) the lattice's barycentric coordinates
        rows = n == m
        out.append((a[rows, None] + u[None, :, None] * (b - a)[rows, None] + v[None, :, None] * (c - a)[rows, None])
                   .reshape(-1, 3))
    return np.concatenate(out) if out else np.zeros((0, 3))


def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N, M) distances from points (N, 3) to triangles (M, 3, 3) (:func:`closest_on_triangles`)."""
    return np.linalg.norm(points[:, None, :] - closest_on_triangles(points, triangles), axis=-1)


def closest_on_triangles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N, M, 3) the point of each triangle (M, 3, 3) nearest each point (N, 3)
    (:func:`closest_points`, every point with every triangle)."""
    return closest_points(points[:, None, :], *(triangles[None, :, k, :] for k in range(3)))


def closest_points(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(..., 3) the point of triangle (a, b, c) nearest p, all (..., 3) and broadcast together, by
    the triangle's Voronoi regions (Ericson, Real-Time Collision Detection, 5.1.5), vectorised
    (float64, numpy): ``PAIRS`` pairs at a time, each coordinate a contiguous array (a distance
    grid's million pairs in 0.23 s, a third of the same arithmetic on (..., 3) tensors in torch)."""
    p, a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (p, a, b, c)))
    flat = [v.reshape(-1, 3) for v in (p, a, b, c)]
    out = np.empty((len(flat[0]), 3))
    for start in range(0, len(out), PAIRS):  # each chunk transposed into rows (in the cache)
        out[start:start + PAIRS] = closest_points_rows(*(np.ascontiguousarray(v[start:start + PAIRS].T)
                                                         for v in flat))
    return out.reshape(p.shape)


def closest_points_rows(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """:func:`closest_points` of points and triangles given as coordinate rows, (3, N) each, float64
    (a caller that has its pairs in rows saves the transposed copies) -> (N, 3); the same values."""
    out = np.empty((p.shape[1], 3))
    for start in range(0, len(out), PAIRS):
        out[start:start + PAIRS] = _closest(*(v[:, start:start + PAIRS] for v in (p, a, b, c)))
    return out


def _closest(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """:func:`closest_points` of (3, N) coordinates each -> (N, 3)."""
    (px, py, pz), (ax, ay, az), (bx, by, bz), (cx, cy, cz) = p, a, b, c
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1, d2 = abx * apx + aby * apy + abz * apz, acx * apx + acy * apy + acz * apz
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3, d4 = abx * bpx + aby * bpy + abz * bpz, acx * bpx + acy * bpy + acz * bpz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5, d6 = abx * cpx + aby * cpy + abz * cpz, acx * cpx + acy * cpy + acz * cpz
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):  # a degenerate triangle: its edges' cases win
        denom = va + vb + vc
        v_face, w_face = vb / denom, vc / denom
        v_ab = np.nan_to_num(d1 / (d1 - d3))
        w_ac = np.nan_to_num(d2 / (d2 - d6))
        w_bc = np.nan_to_num((d4 - d3) / ((d4 - d3) + (d5 - d6)))
    regions = [  # the first that holds wins: vertex a, b, c, edge ab, ac, bc
        (d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (d6 >= 0) & (d5 <= d6),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]
    out = np.empty((len(px), 3))
    for k, (A, AB, AC, B, C) in enumerate(((ax, abx, acx, bx, cx), (ay, aby, acy, by, cy), (az, abz, acz, bz, cz))):
        with np.errstate(invalid="ignore"):  # a degenerate triangle's face point (nan): one of the regions wins
            closest = A + AB * v_face + AC * w_face  # inside the face
        for cond, point in zip(reversed(regions), (B + (C - B) * w_bc, A + AC * w_ac, A + AB * v_ab, C, B, A),
                               strict=True):
            closest = np.where(cond, point, closest)
        out[:, k] = closest
    return out


class MeshQuery:
    """Inside and depth queries on one mesh in its own frame.

    Args:
        mesh: the ``trimesh.Trimesh``.
        pieces: its convex pieces (``ConvexPieces``), the inside of a mesh that is not closed.
    """

    def __init__(self, mesh, pieces=None):
        from scipy.spatial import cKDTree

        self.mesh = mesh
        self.closed = bool(mesh.is_watertight)
        self.pieces = pieces
        self.bounds = np.asarray(mesh.bounds, dtype=np.float64)
        self.triangles = np.asarray(mesh.triangles, dtype=np.float64)  # (M, 3, 3)
        centres = self.triangles.mean(1)
        self._reach = float(np.linalg.norm(self.triangles - centres[:, None], axis=-1).max())
        self._tree = cKDTree(centres)
        self._fine = None

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: points inside the mesh (a closed one by ray tests; else inside a convex piece)."""
        points = np.asarray(points, dtype=np.float64)
        box = np.all((points >= self.bounds[0]) & (points <= self.bounds[1]), axis=1)
        out = np.zeros(len(points), dtype=bool)
        if not box.any():
            return out
        if self.closed or self.pieces is None:
            out[box] = self._contains(points[box])
        else:
            p = points[box]
            planes = self.pieces.planes
            sd = (np.einsum("nc,kfc->nkf", p, planes[..., :3]) - planes[..., 3]).max(-1).min(-1)
            out[box] = sd < 0
        return out

    def _contains(self, points: np.ndarray) -> np.ndarray:
        """Ray parity along one fixed direction, both ways (trimesh's test, deterministic): a point
        whose two rays disagree and both hit (a ray through an edge or a vertex) gets its winding
        number instead of trimesh's retry in a random direction."""
        n = len(points)
        rays = np.tile(RAY, (n, 1))
        _, index, _ = self.mesh.ray.intersects_location(np.vstack((points, points)), np.vstack((rays, -rays)),
                                                        multiple_hits=True)
        hits = np.bincount(index, minlength=2 * n).reshape(2, n)
        odd = hits % 2 == 1
        out = odd[0] & (odd[0] == odd[1])
        broken = (odd[0] != odd[1]) & (hits > 0).all(0)
        if broken.any():
            out[broken] = self.winding(points[broken]) > 0.5
        return out

    def winding(self, points: np.ndarray) -> np.ndarray:
        """(N,) the generalised winding number of points: the solid angle the surface subtends, over
        4 pi (Van Oosterom and Strackee's formula per triangle); 1 inside a closed mesh, 0 outside,
        robust up to the surface (where ray tests can fail) and meaningful for an open mesh. Cost:
        N x triangles."""
        points = np.asarray(points, dtype=np.float64)
        out = np.zeros(len(points))
        for start in range(0, len(points), 64):
            p = points[start:start + 64, None, None, :]
            v = self.triangles[None] - p  # (n, M, 3, 3)
            lengths = np.linalg.norm(v, axis=-1)  # (n, M, 3)
            a, b, c = v[..., 0, :], v[..., 1, :], v[..., 2, :]
            la, lb, lc = lengths[..., 0], lengths[..., 1], lengths[..., 2]
            det = np.einsum("nmi,nmi->nm", a, np.cross(b, c))
            div = la * lb * lc + np.einsum("nmi,nmi->nm", a, b) * lc + np.einsum("nmi,nmi->nm", a, c) * lb \
                + np.einsum("nmi,nmi->nm", b, c) * la
            out[start:start + 64] = (2 * np.arctan2(det, div)).sum(1) / (4 * np.pi)
        return out

    def _vertices(self):
        """A KD-tree over the mesh's triangles cut until every edge is at most ``s``
        (:func:`lattice_points`), and ``h``: every surface point lies within h = s / sqrt(3) of one
        of its points. s = 1 mm, coarser for a large mesh (at most about 200,000 vertices)."""
        if self._fine is None:
            from scipy.spatial import cKDTree

            s = max(SPACING / 2, math.sqrt(float(self.mesh.area) / 200_000))
            self._fine = (cKDTree(lattice_points(self.triangles, s)), s / math.sqrt(3))
        return self._fine

    def distance(self, points: np.ndarray, tolerance: float) -> np.ndarray:
        """(N,) distances to the surface, decided exactly against ``tolerance``: the nearest vertex
        of the finely cut mesh bounds a distance d within [d_v - h, d_v]; points whose bound
        straddles ``tolerance`` get their exact distance to the triangles near them. Distances
        beyond ``MEASURED`` (or beyond the tolerance plus h, if more) are reported as that."""
        tree, h = self._vertices()
        bound = max(MEASURED, tolerance + 2 * h)
        d_v, _ = tree.query(points, distance_upper_bound=bound)  # inf beyond: no vertex that near
        d_v = np.minimum(d_v, bound)
        band = (d_v > tolerance) & (d_v - h <= tolerance)  # undecided against the tolerance
        out = d_v.copy()
        for i in np.nonzero(band)[0]:
            near = self._tree.query_ball_point(points[i], d_v[i] + self._reach)
            out[i] = point_triangle_distance(points[i:i + 1], self.triangles[near]).min()
        return out

    def depths_beyond(self, point_sets: list[np.ndarray], tolerance: float) -> list[float]:
        """For sets of points (each a link's), a depth (m) below the surface that some of its points
        reach beyond ``tolerance``, else 0: one inside test for all the points, then distances
        (:meth:`distance`) of each set's inside points, ``CHUNK`` at a time, until a chunk goes
        deeper than the tolerance (its deepest is reported: a depth reached, not always the
        largest). Exact for the verdict 'deeper than the tolerance'."""
        sizes = [len(p) for p in point_sets]
        if not sum(sizes):
            return [0.0] * len(point_sets)
        points = np.concatenate(point_sets)
        owner = np.repeat(np.arange(len(point_sets)), sizes)
        inside = self.inside(points)
        out = [0.0] * len(point_sets)
        for k in np.unique(owner[inside]):  # each set's inside points, a chunk at a time, until one is deeper
            mine = points[inside & (owner == k)]
            for start in range(0, len(mine), CHUNK):
                depth = self.distance(mine[start:start + CHUNK], tolerance)
                if depth.max() > tolerance:
                    out[k] = float(depth.max())
                    break
        return out

    def depth_beyond(self, points: np.ndarray, tolerance: float) -> float:
        """:meth:`depths_beyond` of one set of points."""
        return self.depths_beyond([np.asarray(points, dtype=np.float64)], tolerance)[0]


def mesh_query(shape) -> tuple[MeshQuery, np.ndarray]:
    """A mesh shape's (a problem's ``Shape``) :class:`MeshQuery` in its own frame (its convex
    pieces stand for the inside of a mesh that is not closed; cached per file and scale), and its
    pose (4, 4) in the world."""
    return _query(mesh_path(shape.mesh), shape.scale), pose_to_matrix_np(shape.pose)


@lru_cache(maxsize=32)
def _query(path: Path, scale: float) -> MeshQuery:
    mesh = load_mesh(path, scale)
    return MeshQuery(mesh, None if mesh.is_watertight else convex_pieces(path, scale))
