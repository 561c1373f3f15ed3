"""Which points of a regular grid lie inside a closed triangle mesh, by the parity of the surface
crossings along the grid's columns: one pass over the triangles, no per-point query."""

from __future__ import annotations

import numpy as np

__all__ = ["JITTER_M", "column_inside"]

JITTER_M = (1.234567e-7, 0.7654321e-7)  # m: the grid columns are moved this far in x and y (off the mesh's
# edges and vertices; unequal, so that a column off a grid point on a diagonal edge is off that edge too)


def column_inside(triangles: np.ndarray, axes: list[np.ndarray]) -> np.ndarray:
    """(nx, ny, nz) bool: the grid points inside a closed mesh (triangles (M, 3, 3)), by the parity
    of the surface crossings below each point on its grid column (a line along z, moved off the
    grid by ``JITTER_M`` so that it meets no edge or vertex of a mesh on the grid)."""
    x, y, z = axes
    shape = (len(x), len(y), len(z))
    a, b, c = (triangles[:, k] for k in range(3))
    lo = tuple(np.searchsorted(g, triangles[:, :, d].min(1) - JITTER_M[d]) for d, g in enumerate((x, y)))
    hi = tuple(np.searchsorted(g, triangles[:, :, d].max(1) - JITTER_M[d], side="right") for d, g in enumerate((x, y)))
    nx, ny = np.maximum(hi[0] - lo[0], 0), np.maximum(hi[1] - lo[1], 0)
    count = nx * ny
    t = np.repeat(np.arange(len(triangles)), count)
    k = np.arange(len(t)) - np.repeat(np.cumsum(count) - count, count)
    i, j = lo[0][t] + k // ny[t], lo[1][t] + k % ny[t]
    px, py = x[i] + JITTER_M[0], y[j] + JITTER_M[1]
    e1, e2 = b[t] - a[t], c[t] - a[t]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    dx, dy = px - a[t, 0], py - a[t, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = (dx * e2[:, 1] - dy * e2[:, 0]) / det, (e1[:, 0] * dy - e1[:, 1] * dx) / det
        hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1)
    zc = a[t, 2][hit] + u[hit] * e1[hit, 2] + v[hit] * e2[hit, 2]  # where the column crosses the triangle
    first = np.clip(np.searchsorted(z, zc), 0, len(z))  # the first grid point above the crossing
    flips = np.zeros((shape[0], shape[1], shape[2] + 1), dtype=np.int64)
    np.add.at(flips, (i[hit], j[hit], first), 1)
    return (np.cumsum(flips, axis=2)[..., :-1] % 2).astype(bool)
