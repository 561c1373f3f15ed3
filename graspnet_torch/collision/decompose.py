"""A mesh cut into convex pieces in bounded time, by planes.

The mesh's *solid* is read on a grid of ``GRID`` cells along its longest side (``h`` apart, at
least ``MIN_CELL_M``): a closed mesh's inside grid points (the parity of surface crossings,
:func:`~graspnet_torch.collision.parity.column_inside`), an open one's the grid points near its
surface (every corner of the cell of each of its surface samples, ``h / 3`` apart: a shell no
axis-aligned step crosses) and those they enclose (an open can's walls and bottom; its inside is
open to the outside and stays out). A point is in the solid where its nearest grid point is.

A *part* is the mesh on one side of each of the cuts that made it, its piece the convex hull of
its *points*: the mesh's vertices on that side, the ends of the mesh's sections by its cuts (each
cut triangle's segment, clipped by the part's other cuts) and the corners where a cut meets two
others well inside the solid (:meth:`_Solid.holds`): the hull of the part of the mesh's surface
and of its cut faces, so the pieces of the two sides of a cut meet there, with no gap between
them. Its *depth* is how far its piece reaches from the solid: the largest distance to the solid
(a Euclidean distance transform of the grid) of ``EMPTY_SAMPLES`` grid points drawn in its
piece, and where.

Starting from the whole mesh, the deepest part is cut, while its depth exceeds ``DEPTH`` of the
mesh's diagonal and ``FLOOR_CELLS`` cells, its piece holds at least ``MIN_CELLS`` cells and there
are fewer than ``MAX_PIECES`` pieces: by the plane through its deepest point, across one of the
three axes or its points' three principal axes, that leaves the shallower pieces (the least depth
of the deeper, from ``SCORE_SAMPLES`` grid points each; then the least volume). A ring is cut
across, through its hole, into arcs; an L at its corner. The time is bounded by the grid and the
number of pieces, not by a search, and the result is deterministic.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.ndimage import binary_fill_holes, distance_transform_edt
from scipy.spatial import ConvexHull, QhullError

from graspnet_torch.collision.parity import column_inside

__all__ = ["DEPTH", "GRID", "MAX_PIECES", "MIN_CELLS", "plane_pieces"]

GRID = 48  # grid cells along the mesh's longest side
MIN_CELL_M = 5e-4  # m: the grid's cells are at least this
DEPTH = 0.02  # a part whose piece reaches at most this share of the mesh's diagonal from its solid is not cut
MAX_PIECES = 24  # pieces at most
FLOOR_CELLS = 1.5  # ... nor one that reaches at most this many cells from it (the grid's own error)
MIN_CELLS = 16  # a part whose piece holds fewer grid cells is not cut
EMPTY_SAMPLES = 2000  # grid points drawn in a piece to measure its depth
SCORE_SAMPLES = 500  # and in a candidate cut's pieces
SEED = 0  # of those draws (deterministic)

Cut = tuple[np.ndarray, float]  # a half-space: (unit normal (3,), offset), normal . x <= offset


class _Part:
    """The mesh on one side of each of a series of cuts (module docstring).

    Attributes:
        points: (n, 3) the points that span its piece (m).
        cuts: the half-spaces it lies in.
        volume: its piece's volume (m^3; 0 where its points span none).
        depth: how far its piece reaches from the solid at most (m): its concavity.
        deepest: (3,) where (m).
    """

    def __init__(self, points: np.ndarray, cuts: tuple[Cut, ...], solid: _Solid, rng: np.random.Generator,
                 hull: ConvexHull | None = None) -> None:
        self.points, self.cuts = points, cuts
        self.hull = _hull(points) if hull is None else hull
        self.volume = 0.0 if self.hull is None else float(self.hull.volume)
        self.depth, self.deepest = (0.0, np.zeros(3)) if self.hull is None else solid.depth(self.hull, rng)

    def vertices(self) -> np.ndarray:
        """(V, 3) its piece's vertices."""
        return self.points[self.hull.vertices]


def plane_pieces(vertices: np.ndarray, faces: np.ndarray, closed: bool) -> list[np.ndarray]:
    """The hull vertices (V_k, 3) of each convex piece of a mesh (vertices (V, 3), m; faces (M, 3)),
    ``closed``: whether it is watertight (module docstring)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = vertices[np.asarray(faces)]
    lo, hi = vertices.min(0), vertices.max(0)
    h = max(float((hi - lo).max()) / GRID, MIN_CELL_M)
    origin = lo - h
    shape = np.ceil((hi - lo) / h).astype(int) + 3
    axes = [origin[d] + h * np.arange(shape[d]) for d in range(3)]
    if closed:
        mask = column_inside(triangles, axes)
    else:
        mask = binary_fill_holes(_shell(_surface_samples(triangles, h / 3), origin, h, shape))

    solid = _Solid(mask, origin, h)
    rng = np.random.default_rng(SEED)
    whole = _Part(vertices, (), solid, rng)
    return [p.vertices() for p in _cut(whole, triangles, h, solid, rng)]


def _cut(whole: _Part, triangles: np.ndarray, h: float, solid: _Solid,
         rng: np.random.Generator) -> list[_Part]:
    """The parts (module docstring), cut from the ``whole`` mesh (triangles (M, 3, 3); ``solid``:
    which points (k, 3) lie in its solid)."""
    if whole.hull is None:
        return []
    heap = [(-whole.depth, 0, whole)]
    deepest = DEPTH * float(np.linalg.norm(np.ptp(whole.points, axis=0)))
    done: list[_Part] = []
    count = 1
    while heap:
        _, _, part = heapq.heappop(heap)
        if (part.depth <= max(deepest, FLOOR_CELLS * h) or part.volume < MIN_CELLS * h ** 3
                or len(heap) + len(done) + 2 > MAX_PIECES):
            done.append(part)
            continue
        found = _best_cut(part, triangles, solid, rng)
        if found is None:
            done.append(part)
            continue
        sides, (normal, at) = found
        for (points, hull), cut in zip(sides, ((normal, at), (-normal, -at)), strict=True):
            child = _Part(points, (*part.cuts, cut), solid, rng, hull)
            if child.hull is not None:
                heapq.heappush(heap, (-child.depth, count, child))
                count += 1
    return done


def _best_cut(part: _Part, triangles: np.ndarray, solid: _Solid, rng: np.random.Generator
              ) -> tuple[list[tuple[np.ndarray, ConvexHull]], Cut] | None:
    """The points and hulls of the two sides (:func:`_sides`) of the cut of ``part`` through its
    deepest point (module docstring) that leaves the shallowest pieces (the least depth of the
    deeper, then the least volume), and the cut; None where none leaves a volume on both sides."""
    principal = np.linalg.svd(part.points - part.points.mean(0), full_matrices=False)[2]
    best, least = None, (np.inf, np.inf)
    for normal in (*np.eye(3), *principal):
        cut = (normal, float(part.deepest @ normal))
        sides = _sides(part, cut, triangles, solid)
        hulls = [_hull(points) for points in sides]
        if any(hull is None for hull in hulls):
            continue
        score = (max(solid.depth(hull, rng, SCORE_SAMPLES)[0] for hull in hulls), sum(hull.volume for hull in hulls))
        if score < least:
            best, least = (list(zip(sides, hulls, strict=True)), cut), score
    return best


def _sides(part: _Part, cut: Cut, triangles: np.ndarray, solid: _Solid) -> tuple[np.ndarray, np.ndarray]:
    """The points of ``part`` below and above ``cut``, each with the mesh's section by the cut
    within the part (the ends of its triangles' segments, clipped by the part's cuts) and the
    corners where the cut meets two of the part's cuts in the solid (module docstring)."""
    normal, at = cut
    first, last = _section(triangles, normal, at)
    for n, offset in part.cuts:
        first, last = _clip(first, last, n, offset)
    section = np.concatenate([first, last, _corners(part.cuts, normal, at, solid)])
    below = part.points @ normal < at
    return np.concatenate([part.points[below], section]), np.concatenate([part.points[~below], section])


class _Solid:
    """The solid on its grid (module docstring): ``mask`` (nx, ny, nz) bool, the first grid point
    ``origin`` (3,) and the spacing ``h`` (m)."""

    def __init__(self, mask: np.ndarray, origin: np.ndarray, h: float) -> None:
        self.mask, self.origin, self.h = mask, origin, h
        self.top = np.asarray(mask.shape) - 1
        self.gap = distance_transform_edt(~mask) * h  # each grid point's distance to the solid (m)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(k,) bool: whether the points (k, 3) lie in the solid (their nearest grid point does)."""
        i = np.clip(np.rint((points - self.origin) / self.h).astype(int), 0, self.top)
        return self.mask[i[:, 0], i[:, 1], i[:, 2]]

    def holds(self, points: np.ndarray) -> np.ndarray:
        """(k,) bool: whether the points (k, 3) lie in a cell of the grid whose corners all lie in the solid."""
        first = np.clip(np.floor((points - self.origin) / self.h).astype(int), 0, self.top - 1)
        out = np.ones(len(points), dtype=bool)
        for corner in np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3):
            c = first + corner
            out &= self.mask[c[:, 0], c[:, 1], c[:, 2]]
        return out

    def depth(self, hull: ConvexHull, rng: np.random.Generator, samples: int = EMPTY_SAMPLES
              ) -> tuple[float, np.ndarray]:
        """How far (m) the grid points in ``hull`` lie from the solid at most, and the farthest
        (3,), over ``samples`` drawn uniformly among those in its box (each grid point's distance
        is exact: its inside is); (0, its box's centre) where none is drawn in it."""
        lo = np.clip(np.ceil((hull.min_bound - self.origin) / self.h).astype(int), 0, self.top)
        hi = np.clip(np.floor((hull.max_bound - self.origin) / self.h).astype(int), lo, self.top)
        i = lo + np.floor(rng.random((samples, 3)) * (hi - lo + 1)).astype(int)
        i = i[((self.origin + i * self.h) @ hull.equations[:, :3].T + hull.equations[:, 3]).max(1) <= 0]
        if not len(i):
            return 0.0, (hull.min_bound + hull.max_bound) / 2
        gap = self.gap[tuple(i.T)]
        k = int(np.argmax(gap))
        return float(gap[k]), self.origin + i[k] * self.h


def _hull(points: np.ndarray) -> ConvexHull | None:
    """The convex hull of points (n, 3), or None where they span no volume."""
    if len(points) < 4:
        return None
    try:
        hull = ConvexHull(points)
    except QhullError:
        return None
    return hull if hull.volume > 0 else None


def _section(triangles: np.ndarray, normal: np.ndarray, at: float) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's section by the plane ``normal . x = at``: each crossing triangle's segment, its
    two ends (m, 3) each."""
    d = triangles @ normal - at  # (M, 3)
    crossing = (d.min(1) < 0) & (d.max(1) >= 0)
    t, d = triangles[crossing], d[crossing]
    ends = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = d[:, i], d[:, j]
        cut = (a < 0) != (b < 0)
        w = np.where(cut, a / np.where(cut, a - b, 1.0), np.nan)
        ends.append(t[:, i] + w[:, None] * (t[:, j] - t[:, i]))
    ends = np.stack(ends, 1)  # (m, 3 edges, 3): two of the three edges cross
    valid = ~np.isnan(ends[..., 0])
    rows = np.arange(len(ends))
    return ends[rows, np.argmax(valid, 1)], ends[rows, 2 - np.argmax(valid[:, ::-1], 1)]


def _clip(first: np.ndarray, last: np.ndarray, normal: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Segments (ends (m, 3) each) clipped to the half-space ``normal . x <= offset``."""
    a, b = first @ normal - offset, last @ normal - offset
    keep = (a <= 0) | (b <= 0)
    first, last, a, b = first[keep], last[keep], a[keep], b[keep]
    w = np.where(a != b, a / np.where(a != b, a - b, 1.0), 0.0)[:, None]
    crossing = first + w * (last - first)  # where a segment leaves the half-space
    return np.where((a > 0)[:, None], crossing, first), np.where((b > 0)[:, None], crossing, last)


def _corners(cuts: tuple[Cut, ...], normal: np.ndarray, at: float, solid: _Solid
             ) -> np.ndarray:
    """(k, 3) where the plane ``normal . x = at`` meets two of ``cuts``' planes, within every cut
    and well inside the solid (:meth:`_Solid.holds`): corners of a part's faces that lie on no
    section of the mesh (one within a cell of the surface is left out: the piece stays within it)."""
    out = []
    for i, (a, oa) in enumerate(cuts):
        for b, ob in cuts[i + 1:]:
            A = np.stack([normal, a, b])
            if abs(np.linalg.det(A)) > 1e-6:
                out.append(np.linalg.solve(A, np.array([at, oa, ob])))
    if not out:
        return np.zeros((0, 3))
    p = np.asarray(out)
    keep = np.all([p @ n <= o + 1e-9 for n, o in cuts], axis=0) & solid.holds(p)
    return p[keep]


def _surface_samples(triangles: np.ndarray, spacing: float) -> np.ndarray:
    """Points over the triangles (M, 3, 3), at most ``spacing`` apart along each triangle's edges
    (each triangle's barycentric grid of ``ceil(longest edge / spacing)`` steps)."""
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max(1)
    steps = np.maximum(np.ceil(edges / spacing).astype(int), 1)
    out = [triangles.reshape(-1, 3)]
    for n in np.unique(steps[steps > 1]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        u, v = i[keep] / n, j[keep] / n  # (P,)
        t = triangles[steps == n]  # (m, 3, 3)
        out.append((t[:, 0, None] * (1 - u - v)[None, :, None] + t[:, 1, None] * u[None, :, None]
                    + t[:, 2, None] * v[None, :, None]).reshape(-1, 3))
    return np.concatenate(out)


def _thin(points: np.ndarray, size: float) -> np.ndarray:
    """Indices of points (n, 3), one per cube of side ``size`` that holds any."""
    cell = np.floor(points / size).astype(np.int64)
    cell -= cell.min(0)
    span = cell.max(0) + 1
    return np.unique((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2], return_index=True)[1]


def _shell(samples: np.ndarray, origin: np.ndarray, h: float, shape: np.ndarray) -> np.ndarray:
    """(nx, ny, nz) bool: every corner of the grid cell of each surface sample (n, 3)."""
    out = np.zeros(tuple(shape), dtype=bool)
    first = np.clip(np.floor((samples - origin) / h).astype(int), 0, shape - 2)
    first = first[_thin(first, 1)]
    for corner in np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3):
        c = first + corner
        out[c[:, 0], c[:, 1], c[:, 2]] = True
    return out
