"""Mesh objects and obstacles as FCL sees them: the mesh itself, its inside, and how deep a link goes in.

FCL checks a triangle mesh as a BVH of its triangles: it finds where a link's geometry crosses
the surface, but not a link wholly inside, and its penetration depths against a mesh are those of
single triangles (measured: negative, or the triangle's, not the object's). So for a mesh the
engine of record adds two measurements of its own, against the mesh itself:

- *inside*: a point is inside a closed (watertight) mesh by trimesh's ray test; a mesh that is not
  closed has no inside of its own, and its convex pieces (:mod:`graspnet_torch.collision.convex`)
  stand for it;
- *depth* of a link: the largest depth below the surface of points spread over the link's
  geometry (its surface, at most ``SPACING`` apart, and its vertices), i.e. how far the link
  reaches into the object.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["MeshQuery", "load_mesh", "mesh_bvh", "mesh_query", "shape_points"]

SPACING = 0.001  # m between the points that measure a link's depth
MAX_POINTS = 4000


@lru_cache(maxsize=32)
def load_mesh(path: Path, scale: float = 1.0):
    """A mesh file as one ``trimesh.Trimesh`` (a scene's geometry concatenated; vertices split by
    texture seams or normals merged, so that a closed surface is watertight), scaled; cached per
    process: do not modify it."""
    import trimesh

    mesh = trimesh.load(Path(path), force="mesh")
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if scale != 1.0:
        mesh.apply_scale(scale)
    return mesh


@lru_cache(maxsize=32)
def mesh_bvh(path: Path, scale: float = 1.0):
    """The FCL BVH model of a mesh file (cached; shared by the collision objects that use it)."""
    from graspnet_torch.collision.scene import fcl_geometry

    return fcl_geometry("mesh", (), load_mesh(path, scale))


def shape_points(kind: str, size: tuple[float, ...], mesh=None) -> np.ndarray:
    """(N, 3) points spread over a shape's surface (at most ``SPACING`` apart, at most
    ``MAX_POINTS``), its vertices included, in the shape's own frame: a box (full extents), a
    cylinder (radius, length along z), a sphere (radius,) or a mesh (a ``trimesh.Trimesh``)."""
    import trimesh

    if kind == "box":
        surface = trimesh.creation.box(extents=size)
    elif kind == "cylinder":
        surface = trimesh.creation.cylinder(radius=size[0], height=size[1], sections=32)
    elif kind == "sphere":
        surface = trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    else:
        surface = mesh
    count = min(MAX_POINTS, max(64, math.ceil(surface.area / SPACING**2)))
    samples, _ = trimesh.sample.sample_surface_even(surface, count, seed=0)
    return np.concatenate([np.asarray(surface.vertices, dtype=np.float64), np.asarray(samples, dtype=np.float64)])


class MeshQuery:
    """Inside and depth queries on one mesh in its own frame.

    Args:
        mesh: the ``trimesh.Trimesh``.
        pieces: its convex pieces (``ConvexPieces``), the inside of a mesh that is not closed.
    """

    def __init__(self, mesh, pieces=None):
        import trimesh

        self.mesh = mesh
        self.closed = bool(mesh.is_watertight)
        self.pieces = pieces
        self._proximity = trimesh.proximity.ProximityQuery(mesh)
        self.bounds = np.asarray(mesh.bounds, dtype=np.float64)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: points inside the mesh (a closed one by ray tests; else inside a convex piece)."""
        points = np.asarray(points, dtype=np.float64)
        box = np.all((points >= self.bounds[0]) & (points <= self.bounds[1]), axis=1)
        out = np.zeros(len(points), dtype=bool)
        if not box.any():
            return out
        if self.closed or self.pieces is None:
            out[box] = self.mesh.contains(points[box])
        else:
            p = points[box]
            planes = self.pieces.planes
            sd = (np.einsum("nc,kfc->nkf", p, planes[..., :3]) - planes[..., 3]).max(-1).min(-1)
            out[box] = sd < 0
        return out

    def depth(self, points: np.ndarray) -> float:
        """The largest depth (m) of points below the surface (0 when none is inside)."""
        points = np.asarray(points, dtype=np.float64)
        inside = self.inside(points)
        if not inside.any():
            return 0.0
        _, distance, _ = self._proximity.on_surface(points[inside])
        return float(np.max(distance))


def mesh_query(shape) -> tuple[MeshQuery, np.ndarray]:
    """A mesh shape's (a problem's ``Shape``) :class:`MeshQuery` in its own frame (its convex
    pieces stand for the inside of a mesh that is not closed), and its pose (4, 4) in the world."""
    from graspnet_torch.collision.convex import convex_pieces
    from graspnet_torch.robot.chain import rpy_matrix_np

    path = Path(shape.mesh).resolve()
    mesh = load_mesh(path, shape.scale)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rpy_matrix_np(shape.pose[3:]), shape.pose[:3]
    return MeshQuery(mesh, None if mesh.is_watertight else convex_pieces(path, shape.scale)), T
