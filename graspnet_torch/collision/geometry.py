"""FCL geometry of shapes: primitives, triangle meshes (a mesh file's BVH, built once) and poses.

The one place python-fcl objects are made from this package's shapes; :mod:`~graspnet_torch.collision.scene`
places them, and the tests compare against them.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from graspnet_torch.meshes import load_mesh

__all__ = ["fcl_geometry", "fcl_transform", "link_geometry", "mesh_bvh"]


def fcl_geometry(kind: str, size: tuple[float, ...], mesh=None):
    """An FCL geometry: box (full extents), cylinder (radius, length along z), sphere (radius), or
    a triangle mesh (a ``trimesh.Trimesh`` in its own frame)."""
    import fcl

    if kind == "box":
        return fcl.Box(*size)
    if kind == "cylinder":
        return fcl.Cylinder(size[0], size[1])
    if kind == "sphere":
        return fcl.Sphere(size[0])
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


def link_geometry(shape) -> object:
    """The FCL geometry of a link's shape (``robot.geometry.LinkShape``): a primitive, or a mesh as a
    ``BVHModel`` of its triangles (a surface: FCL finds where it crosses another geometry, not a
    geometry wholly inside a closed mesh)."""
    return fcl_geometry(shape.kind, shape.size, shape.mesh)


@lru_cache(maxsize=32)
def mesh_bvh(path: Path, scale: float = 1.0):
    """The FCL BVH model of a mesh file (cached; shared by the collision objects that use it)."""
    return fcl_geometry("mesh", (), load_mesh(path, scale))


def fcl_transform(T: np.ndarray):
    """An FCL transform from a pose (4, 4)."""
    import fcl

    return fcl.Transform(T[:3, :3], T[:3, 3])
