"""Oriented boxes around collision shapes and the separating-axis test between them, batched: the
broad phase of :class:`~graspnet_torch.collision.scene.CollisionScene`.

Every shape lies inside its box (a box is its own; a cylinder (r, L) the box r x r x L/2 half
extents along its axis; a sphere the cube around it; a mesh the box of its vertices in its
frame), so two shapes whose boxes are apart are apart: only the pairs whose boxes meet go to the
exact test (FCL), and a posture none of whose pairs meet is clear without it.

Two oriented boxes A, B (rotations R_a, R_b, centres t_a, t_b, half extents a, b) are apart iff
one of 15 axes separates them (Gottschalk et al., "OBBTree", 1996): with R = R_a^T R_b,
t = R_a^T (t_b - t_a) and |R| + eps,

    A's faces   i:     |t_i|                          > a_i + sum_j b_j |R_ij|
    B's faces   j:     |t . R_:j|                     > sum_i a_i |R_ij| + b_j
    edges  i x j:      |t_i2 R_i1,j - t_i1 R_i2,j|    > a_i1 |R_i2,j| + a_i2 |R_i1,j|
                                                        + b_j1 |R_i,j2| + b_j2 |R_i,j1|

(i1, i2 = i + 1, i + 2 mod 3; j likewise). The eps keeps near-parallel edges from separating
boxes that touch; a ``margin`` grows A's half extents, so boxes closer than it count as meeting.
"""

from __future__ import annotations

import numpy as np

from graspnet_torch.meshes import load_mesh, mesh_path
from graspnet_torch.robot.geometry import LinkShape
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np

__all__ = ["BOX_MARGIN_M", "boxes_apart", "link_box", "shape_box"]

BOX_MARGIN_M = 1e-4  # boxes closer than this count as meeting (FCL's tolerances are far below it)
_EPS = 1e-9
_NEXT = np.array([1, 2, 0])
_AFTER = np.array([2, 0, 1])


def _primitive_half(kind: str, size: tuple[float, ...]) -> np.ndarray:
    if kind == "box":
        return np.asarray(size, dtype=np.float64) / 2
    if kind == "cylinder":
        return np.array([size[0], size[0], size[1] / 2], dtype=np.float64)
    if kind == "sphere":
        return np.full(3, float(size[0]))
    raise ValueError(f"no box for a shape of kind '{kind}'")


def _vertices_box(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = vertices.min(0), vertices.max(0)
    T = np.eye(4)
    T[:3, 3] = (lo + hi) / 2
    return T, (hi - lo) / 2


def link_box(shape: LinkShape) -> tuple[np.ndarray, np.ndarray]:
    """A link shape's box: its pose (4, 4) in the link's frame and half extents (3,)."""
    if shape.kind == "mesh":
        T, half = _vertices_box(np.asarray(shape.mesh.vertices, dtype=np.float64))
        return shape.origin @ T, half
    return np.array(shape.origin, dtype=np.float64), _primitive_half(shape.kind, shape.size)


def shape_box(shape: Shape) -> tuple[np.ndarray, np.ndarray]:
    """An obstacle's or object's box: its pose (4, 4) in the world and half extents (3,)."""
    pose = pose_to_matrix_np(np.asarray(shape.pose, dtype=np.float64))
    if shape.kind == "mesh":
        mesh = load_mesh(mesh_path(shape.mesh), shape.scale)
        T, half = _vertices_box(np.asarray(mesh.vertices, dtype=np.float64))
        return pose @ T, half
    return pose, _primitive_half(shape.kind, shape.size)


def boxes_apart(Ta: np.ndarray, ha: np.ndarray, Tb: np.ndarray, hb: np.ndarray, margin: float = BOX_MARGIN_M
                ) -> np.ndarray:
    """Whether boxes are apart (module docstring), broadcast over the leading dimensions.

    Ta, Tb: (..., 4, 4) poses; ha, hb: (..., 3) half extents -> (...) bool: True where an axis
    separates them by more than ``margin`` (False: they meet, or may)."""
    Ra, Rb = Ta[..., :3, :3], Tb[..., :3, :3]
    ha = ha + margin
    R = np.swapaxes(Ra, -1, -2) @ Rb  # B's axes in A's frame
    t = (np.swapaxes(Ra, -1, -2) @ (Tb[..., :3, 3] - Ta[..., :3, 3])[..., None])[..., 0]
    A = np.abs(R) + _EPS
    apart = (np.abs(t) > ha + (A @ hb[..., None])[..., 0]).any(-1)
    tb = (t[..., None, :] @ R)[..., 0, :]
    apart |= (np.abs(tb) > (ha[..., None, :] @ A)[..., 0, :] + hb).any(-1)
    i1, i2 = _NEXT, _AFTER
    L = t[..., i2, None] * R[..., i1, :] - t[..., i1, None] * R[..., i2, :]  # (..., 3, 3): axis a_i x b_j
    ra = ha[..., i1, None] * A[..., i2, :] + ha[..., i2, None] * A[..., i1, :]
    rb = hb[..., None, i1] * A[..., :, i2] + hb[..., None, i2] * A[..., :, i1]
    apart |= (np.abs(L) > ra + rb).any((-1, -2))
    return apart
