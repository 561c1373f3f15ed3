"""An object's surface at given points: outward normals and signed distances, and where a finger's
tip must be for its pad to touch a contact (the "surface" contact model).

Primitives are measured analytically in the shape's own frame (its pose (x, y, z, rx, ry, rz),
metres and radians, undone first):

- box (full extents s): the face of the largest ``|p_i| - s_i / 2`` (the nearest face for a point
  inside or on the surface; an edge or a corner takes one of its faces), normal ``sign(p_i) e_i``;
- cylinder (radius r, height h along z): radial ``(x, y, 0) / rho`` where ``rho - r >= |z| - h / 2``
  (the side is the nearer surface), else ``sign(z) e_z`` (a cap);
- sphere: radial.

A mesh object (its :func:`~graspnet_torch.collision.mesh.mesh_query`: the mesh at its scale, placed
by its pose) is measured from the mesh: the exact closest point of its triangles; on the surface
(within ``ON_SURFACE``) the normal is that triangle's face normal, off it the direction from the
closest point to the point (away from it when outside, towards it when inside: the distance's
gradient, outward either way). Distances are signed: positive outside.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from graspnet_torch.collision.mesh import closest_points, mesh_query
from graspnet_torch.collision.sdf import distance_grid
from graspnet_torch.errors import ProblemError
from graspnet_torch.meshes import mesh_path
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.tasks import GraspProblem

__all__ = ["NEAR_ERROR_M", "ON_SURFACE", "pad_targets", "surface_distance", "surface_distance_near",
           "surface_distance_within", "surface_normals", "touch_points"]

ON_SURFACE = 1e-7  # m: a mesh point this near its closest surface point takes that triangle's normal
NEAR_ERROR_M = 1e-3  # m: surface_distance_near's bound on a mesh's error near its surface (measured: module tests)


def _local(obj: Shape, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points (k, 3) in the shape's frame, and the shape's rotation (3, 3); ValueError for a
    shape of no known kind."""
    if obj.kind not in ("box", "cylinder", "sphere", "mesh"):
        raise ValueError(f"surface: unknown shape kind '{obj.kind}'")
    T = pose_to_matrix_np(obj.pose)
    shifted = np.asarray(points, dtype=np.float64).reshape(-1, 3) - T[:3, 3]
    return (T[:3, :3].T @ shifted.T).T, T[:3, :3]  # (shifted @ R), as one product over the long axis


def _excess(obj: Shape, p: np.ndarray) -> np.ndarray:
    """How far points (k, 3), in a box's or cylinder's frame, lie beyond each pair of its faces:
    (k, 3) a box's, (k, 2) a cylinder's (radially, axially)."""
    if obj.kind == "box":
        return np.abs(p) - np.asarray(obj.size) / 2
    return np.stack([np.linalg.norm(p[:, :2], axis=1) - obj.size[0], np.abs(p[:, 2]) - obj.size[1] / 2], axis=1)


def _primitive_distance(obj: Shape, p: np.ndarray) -> np.ndarray:
    """Signed distances (k,) of points (k, 3) in a primitive's frame to its surface."""
    if obj.kind == "sphere":
        return np.linalg.norm(p, axis=1) - obj.size[0]
    q = _excess(obj, p)
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _primitive(obj: Shape, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals (k, 3) and signed distances (k,) of a primitive, in its frame."""
    k = len(p)
    if obj.kind == "sphere":
        norm = np.linalg.norm(p, axis=1)
        n = np.where(norm[:, None] > 0, p / np.where(norm > 0, norm, 1.0)[:, None], [0.0, 0.0, 1.0])
        return n, _primitive_distance(obj, p)
    q = _excess(obj, p)
    if obj.kind == "box":
        axis = np.argmax(q, axis=1)
        n = np.zeros((k, 3))
        n[np.arange(k), axis] = np.where(p[np.arange(k), axis] < 0, -1.0, 1.0)
    else:  # cylinder
        rho = np.linalg.norm(p[:, :2], axis=1)
        side = q[:, 0] >= q[:, 1]
        radial = np.concatenate([p[:, :2] / np.where(rho > 0, rho, 1.0)[:, None], np.zeros((k, 1))], axis=1)
        radial[rho == 0] = [1.0, 0.0, 0.0]
        cap = np.zeros((k, 3))
        cap[:, 2] = np.where(p[:, 2] < 0, -1.0, 1.0)
        n = np.where(side[:, None], radial, cap)
    return n, _primitive_distance(obj, p)


def _centres(path: Path, scale: float) -> tuple[cKDTree, float]:
    """A KD-tree of a mesh object's triangle centres and the largest centre-to-vertex distance."""
    triangles = mesh_query(Shape("mesh", (), np.zeros(6), path, scale))[0].triangles
    centres = triangles.mean(1)
    return cKDTree(centres), float(np.linalg.norm(triangles - centres[:, None], axis=-1).max())


def _mesh(obj: Shape, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals (k, 3) and signed distances (k,) of a mesh object, in its frame: each
    point's nearest triangle among those whose centres could be near enough (a KD-tree), exactly."""
    query, _ = mesh_query(obj)
    tree, reach = _centres(mesh_path(obj.mesh), obj.scale)
    triangles, face_normals = query.triangles, np.asarray(query.mesh.face_normals, dtype=np.float64)
    if not len(p):
        return np.zeros((0, 3)), np.zeros(0)
    near, _ = tree.query(p)
    sign = np.where(query.inside(p), -1.0, 1.0)
    lists = tree.query_ball_point(p, near + reach + 1e-12, return_sorted=False)  # each point's candidates
    counts = np.array([len(c) for c in lists])
    idx = np.concatenate([np.asarray(c, dtype=int) for c in lists])
    owner = np.repeat(np.arange(len(p)), counts)
    candidates = closest_points(p[owner], *(triangles[idx, k] for k in range(3)))  # (pairs, 3)
    gap = np.linalg.norm(candidates - p[owner], axis=-1)
    start = np.cumsum(counts) - counts
    best = np.minimum.reduceat(gap, start)
    ties = np.flatnonzero(gap == np.repeat(best, counts))
    first = ties[np.unique(owner[ties], return_index=True)[1]]
    closest, j = candidates[first], idx[first]  # each point's nearest (the first of equals, in the tree's order)
    dist = np.linalg.norm(p - closest, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.where((dist > ON_SURFACE)[:, None], sign[:, None] * (p - closest) / dist[:, None], face_normals[j])
    return n, sign * dist


def _measure(obj: Shape, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World normals (k, 3) and signed distances (k,)."""
    p, R = _local(obj, points)
    n, d = _mesh(obj, p) if obj.kind == "mesh" else _primitive(obj, p)
    return (R @ n.T).T, d


def surface_normals(obj: Shape, points: np.ndarray) -> np.ndarray:
    """(k, 3) the object's outward unit normals, world frame, at (or nearest to) world points
    ``points`` (k, 3) (module docstring: which face a point on an edge takes)."""
    return _measure(obj, points)[0]


def surface_distance(obj: Shape, points: np.ndarray) -> np.ndarray:
    """(k,) signed distances (m) of world points ``points`` (k, 3) to the object's surface:
    positive outside, negative inside (exact for primitives; a mesh: to its triangles, the sign by
    its inside test, :class:`~graspnet_torch.collision.mesh.MeshQuery`)."""
    return _measure(obj, points)[1]


def surface_distance_near(obj: Shape, points: np.ndarray) -> np.ndarray:
    """(k,) :func:`surface_distance`, fast and near: exact for primitives; for a mesh, read off its
    signed distance grid (:func:`~graspnet_torch.collision.sdf.distance_grid`: 1.5 mm cells,
    trilinear; within ``NEAR_ERROR_M`` of the exact distance near the surface, where measured), its
    sign by the parity of surface crossings (which is right where the ray test of
    :func:`surface_distance` misses a crossing). For searches that call it on many points (a grasp
    sampler's closing lines, about 0.2 microseconds a point), which ask only whether a sphere
    touches; the exact one checks what they find."""
    p, _ = _local(obj, points)
    return distance_grid(obj)(p) if obj.kind == "mesh" else _primitive_distance(obj, p)


def surface_distance_within(obj: Shape, points: np.ndarray, within_m: float) -> np.ndarray:
    """(k,) :func:`surface_distance` where it is at most ``within_m`` (m), exact there; elsewhere a
    value over ``within_m`` (:func:`surface_distance_near`'s, which is exact only for primitives):
    a mesh's exact distance is measured only at the points whose near one lies within
    ``within_m + 2 NEAR_ERROR_M``. For asking which of many points (a link's surface) lie near."""
    near = surface_distance_near(obj, points)
    if obj.kind != "mesh":
        return near
    close = near <= within_m + 2 * NEAR_ERROR_M
    out = np.maximum(near, within_m + 1e-9)
    if close.any():
        out[close] = surface_distance(obj, points[close])
    return out


def touch_points(obj: Shape, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where world points (k, 3) near the object touch its surface: the nearest surface points
    (k, 3), the outward unit normals there (k, 3) and how far those points lie off the surface
    (k,) (a primitive's nearest point is exact; on an edge or corner the normal is one face's, which
    may put the point off it, see :func:`surface_normals`). A mesh's come from trimesh's closest
    point (its R-tree; within 20 micrometres of the exact distance where measured) and that
    triangle's normal, on the surface by construction: one pass, for searches over many points."""
    if not len(points):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    if obj.kind != "mesh":
        n, d = _measure(obj, points)
        contacts = np.asarray(points, dtype=np.float64).reshape(-1, 3) - d[:, None] * n
        n_at, d_at = _measure(obj, contacts)
        return contacts, n_at, np.abs(d_at)
    import trimesh

    p, R = _local(obj, points)
    query, _ = mesh_query(obj)
    closest, _, triangle = trimesh.proximity.closest_point(query.mesh, p)
    normals = np.asarray(query.mesh.face_normals, dtype=np.float64)[triangle]
    T = pose_to_matrix_np(obj.pose)
    return np.asarray(closest) @ R.T + T[:3, 3], normals @ R.T, np.zeros(len(p))


def pad_targets(robot: Robot, problem: GraspProblem) -> np.ndarray:
    """(k, 3) world positions of the tip frames of the problem's contact fingers (its ``fingers``
    order) that put each finger's pad (:attr:`Robot.pads <graspnet_torch.robot.robot.Robot.pads>`)
    on its contact c with the pad normal along the object's inward normal ``-n`` (n: the outward
    normal at c, :func:`surface_normals`).

    With the tip frame's rotation R chosen so that ``R normal = -n``, the tip lies at
    ``c - R point``; the pad point's component along its normal gives ``c + depth n``
    (``depth = point . normal``), which is what is returned: exact for a pad on its tip's normal
    line (every derived pad whose normal line meets the distal surface, e.g. the shipped hand's),
    and for any other pad its sideways offset is left out (it turns with R about n, which a
    position target cannot fix).
    """
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    if not len(contacts):
        return contacts
    if problem.object is None:
        raise ProblemError(f"{problem.source}: the surface contact model needs the problem's object (its "
                           f"normals at the contacts)")
    pads = robot.pads
    depth = np.array([pads[robot.finger_names[robot.finger_index(f)]].depth for f in problem.fingers])
    return contacts + depth[:, None] * surface_normals(problem.object, contacts)
