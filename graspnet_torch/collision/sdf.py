"""A mesh's signed distance on a regular grid, read by trilinear interpolation: for searches that
ask millions of times whether a sphere touches or enters an object (a grasp sampler's closing
lines), which the exact distance (a nearest triangle per point) cannot answer at that rate.

The grid covers the mesh's bounding box and ``MARGIN_M`` around it, ``CELL_M`` apart; a mesh whose
grid would hold more than ``MAX_CELLS`` points (over about 38 cm a side, margins included) gets
coarser cells, as many as that, and a band grown with them (a 1 m cube: 4.1 mm cells; at 1.5 mm it
would take 333 million points, gigabytes and minutes). A grid point within ``BAND_M`` of the
surface (times the cell over ``CELL_M``) holds its exact distance (every triangle whose box grown
by ``BAND_M`` holds the point is measured, :func:`~graspnet_torch.collision.mesh.closest_points`);
a point farther holds an upper bound, the nearest such point's distance plus the way to it (a
Euclidean distance transform of the band); the sign is the mesh's inside test at the point
(:meth:`~graspnet_torch.collision.mesh.MeshQuery.inside`; a closed mesh's by the parity of surface
crossings along grid columns, an open one's convex pieces each on the grid points in its box).
Between grid points the value is interpolated (exact on a flat face; within ``ERROR_M`` of the
exact distance near the surface where measured, see
:func:`graspnet_torch.collision.surface.surface_distance_near`); a point off the grid gets its
nearest grid point's value plus the way to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import HalfspaceIntersection, QhullError

from graspnet_torch.collision.mesh import MeshQuery, closest_points_rows, mesh_query
from graspnet_torch.collision.parity import column_inside
from graspnet_torch.meshes import mesh_path
from graspnet_torch.robot.shape import Shape

__all__ = ["BAND_M", "CELL_M", "MARGIN_M", "MAX_CELLS", "DistanceGrid", "distance_grid"]

CELL_M = 1.5e-3  # m between grid points
BAND_M = 3e-3  # m: grid points this near the surface hold the exact distance (>= CELL_M sqrt(3))
MARGIN_M = 0.02  # m of grid around the mesh's bounding box
MAX_CELLS = 1 << 24  # grid points at most (float64: 134 MB); a larger mesh's cells grow
PAIRS = 1 << 15  # (grid point, triangle) pairs measured at once (the arrays stay in the cache)
PIECE_PAD_M = 1e-9  # m: a convex piece's box, grown by this, holds every point its planes call inside


@dataclass(frozen=True)
class DistanceGrid:
    """A signed distance field on a grid (module docstring), object frame.

    Attributes:
        origin: (3,) the first grid point (m).
        cell: the spacing (m).
        values: (nx, ny, nz) the signed distances (m; positive outside).
    """

    origin: np.ndarray
    cell: float
    values: np.ndarray

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(k,) the signed distance at points (k, 3), object frame (trilinear)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        shape = self.values.shape
        top = np.asarray(shape) - 1
        u = (p - self.origin) / self.cell
        inside = np.clip(u, 0.0, top)
        outside = u - inside
        i = np.minimum(inside.astype(np.intp), top - 1)  # the cell's first corner (inside >= 0: the floor)
        fx, fy, fz = (inside - i).T
        sx, sy = shape[1] * shape[2], shape[2]  # the flat grid's strides along x and y (z: 1)
        corners = self.values.reshape(-1)[(i[:, 0] * sx + i[:, 1] * sy + i[:, 2])[:, None] + np.array(
            [0, sx, 1, sx + 1, sy, sx + sy, sy + 1, sx + sy + 1])]  # (k, 8): one gather
        gx, gy, gz = 1 - fx, 1 - fy, 1 - fz
        c00 = corners[:, 0] * gx + corners[:, 1] * fx
        c01 = corners[:, 2] * gx + corners[:, 3] * fx
        c10 = corners[:, 4] * gx + corners[:, 5] * fx
        c11 = corners[:, 6] * gx + corners[:, 7] * fx
        d = (c00 * gy + c10 * fy) * gz + (c01 * gy + c11 * fy) * fz
        if outside.any():  # beyond the grid: plus the distance to it
            d = d + np.linalg.norm(outside, axis=1) * self.cell
        return d

def distance_grid(obj: Shape) -> DistanceGrid:
    """A mesh object's :class:`DistanceGrid` (its mesh at its scale, object frame; cached per file
    and scale)."""
    return _grid(mesh_path(obj.mesh), obj.scale)


@lru_cache(maxsize=32)
def _grid(path: Path, scale: float) -> DistanceGrid:
    query = mesh_query(Shape("mesh", (), np.zeros(6), path, scale))[0]
    origin = query.bounds[0] - MARGIN_M
    extent = query.bounds[1] + MARGIN_M - origin
    cell = max(CELL_M, float(np.prod(extent + CELL_M) / MAX_CELLS) ** (1 / 3))
    while np.prod(np.ceil(extent / cell) + 1) > MAX_CELLS:  # rounding up each axis: a little coarser
        cell *= 1.01
    band = BAND_M * (cell / CELL_M)
    shape = np.ceil(extent / cell).astype(int) + 1
    axes = [origin[d] + cell * np.arange(shape[d]) for d in range(3)]
    exact = _band(query.triangles, origin, shape, cell, band)
    known = exact < band
    far, nearest = distance_transform_edt(~known.reshape(shape), return_indices=True)
    bound = exact[np.ravel_multi_index(tuple(nearest.reshape(3, -1)), shape)] + far.ravel() * cell
    unsigned = np.where(known, exact, np.minimum(exact, bound))
    if query.closed:
        inside = column_inside(query.triangles, axes).ravel()
    elif query.pieces is None:  # the mesh's own test
        inside = query.inside(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))
    else:
        inside = _inside_pieces(query, axes).ravel()
    return DistanceGrid(origin, cell, np.where(inside, -unsigned, unsigned).reshape(shape))


def _inside_pieces(query: MeshQuery, axes: list[np.ndarray]) -> np.ndarray:
    """(nx, ny, nz) bool: the grid points inside a mesh that is not closed, as its own test has it
    (:meth:`~graspnet_torch.collision.mesh.MeshQuery.inside`: within the mesh's bounds, inside one of
    its convex pieces), each piece tested only on the grid points in the box of its planes' polytope
    (``PIECE_PAD_M`` wider; the mesh's bounds where that cannot be found)."""
    out = np.zeros(tuple(len(a) for a in axes), dtype=bool)
    for planes, v in zip(query.pieces.planes, query.pieces.vertices, strict=True):
        lo, hi = query.bounds
        try:  # the planes' polytope can be larger than the hull of the piece's vertices (planes dropped)
            corners = HalfspaceIntersection(np.column_stack([planes[:, :3], -planes[:, 3]]), v.mean(0)).intersections
            lo, hi = np.maximum(corners.min(0) - PIECE_PAD_M, lo), np.minimum(corners.max(0) + PIECE_PAD_M, hi)
        except (QhullError, ValueError):
            pass
        box = tuple(slice(np.searchsorted(a, lo[d]), np.searchsorted(a, hi[d], side="right"))
                    for d, a in enumerate(axes))
        p = np.stack(np.meshgrid(*(a[b] for a, b in zip(axes, box, strict=True)), indexing="ij"), axis=-1)
        out[box] |= (np.einsum("...c,fc->...f", p, planes[:, :3]) - planes[:, 3]).max(-1) < 0
    return out


def _band(triangles: np.ndarray, origin: np.ndarray, shape: np.ndarray, cell: float, band: float) -> np.ndarray:
    """(prod(shape),) each grid point's (``cell`` apart) least distance to the triangles (M, 3, 3)
    whose boxes grown by ``band`` hold it (inf where none does): exact below ``band``. The (grid
    point, triangle) pairs are laid out in coordinate rows, each a contiguous array."""
    lo = np.clip(np.floor((triangles.min(1) - band - origin) / cell).astype(int), 0, shape - 1)
    hi = np.clip(np.ceil((triangles.max(1) + band - origin) / cell).astype(int), 0, shape - 1)
    ext = hi - lo + 1  # (M, 3) grid points per axis in each grown box
    count = ext.prod(1)
    corners = np.ascontiguousarray(triangles.transpose(1, 2, 0))  # (vertex, coordinate, M)
    out = np.full(int(shape.prod()), np.inf)
    start = 0
    while start < len(triangles):
        stop = start + max(1, int(np.searchsorted(np.cumsum(count[start:]), PAIRS)))
        t = np.repeat(np.arange(start, stop), count[start:stop])
        k = np.arange(len(t)) - np.repeat(np.cumsum(count[start:stop]) - count[start:stop], count[start:stop])
        ny, nz = ext[t, 1], ext[t, 2]
        i = lo[t, 0] + k // (ny * nz), lo[t, 1] + k // nz % ny, lo[t, 2] + k % nz  # each pair's grid point
        p = np.stack([origin[d] + i[d] * cell for d in range(3)])  # (3, N)
        near = closest_points_rows(p, *(corners[v][:, t] for v in range(3)))
        d = np.linalg.norm(p.T - near, axis=1)
        np.minimum.at(out, (i[0] * shape[1] + i[1]) * shape[2] + i[2], d)
        start = stop
    return out
