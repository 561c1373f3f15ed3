"""Mesh objects and obstacles as convex pieces, for the loop's collision proxy.

A triangle mesh (a user's STL, OBJ, PLY or GLB) is cut into convex pieces once (a mesh that is
already convex is its own hull, one piece): by CoACD (the ``coacd`` package: collision-aware
concavity and a tree search, here a shallow one) within ``COACD_BUDGET_S``; where it runs longer or
fails, by planes through the mesh's deepest concavities
(:mod:`~graspnet_torch.collision.decompose`: bounded in time, deterministic, a looser fit). The
pieces are cached on disk per mesh content and scale (:func:`convex_pieces`).

Each piece is the intersection of its faces' half-spaces n . x <= b (n unit, outward), so its
signed distance, batched in torch, is

    sd(x) = max_f (n_f . x - b_f)                                        (:func:`pieces_distance`)

exact inside the piece and wherever the nearest feature is a face; near an edge or a vertex it
is a lower bound (the piece looks up to sqrt(3) times closer from beyond a corner), so a sphere
(c, rho) hits the piece when sd(c) < rho: a conservative test. Bevel planes at the sharp edges
and corners (supporting planes, not faces) bring that bound near the true distance there. The mesh is the union of its
pieces (sd = min over pieces).

FCL, the engine of record, checks the mesh itself (a BVH of its triangles, with the inside and
the depth measured against the mesh: :mod:`graspnet_torch.collision.mesh`); tests measure how
often the two verdicts agree.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.decompose import DEPTH, GRID, MAX_PIECES, MIN_CELLS, plane_pieces
from graspnet_torch.io import atomic_path
from graspnet_torch.meshes import load_mesh, mesh_path

__all__ = ["ConvexPieces", "cache_dir", "coacd_apart", "convex_pieces", "piece_distance", "pieces_distance"]

VERSION = 9  # of the cached files: bump when the decomposition changes
COACD = {"threshold": 0.05, "max_ch_vertex": 32, "seed": 0,  # CoACD's concavity threshold (its default) ...
         "mcts_iterations": 30, "mcts_nodes": 10, "mcts_max_depth": 2, "resolution": 1000}  # ... a shallow search
COACD_BUDGET_S = 2.0  # s: CoACD running longer is stopped, and the mesh cut by planes instead
CONVEX_VOLUME_RATIO = 1.001  # a mesh whose hull holds at most this much more volume is convex: one piece
MAX_PLANES = 64  # planes of a piece: its faces, then bevels; a hull of more faces is bounded by this many
BEVEL_COS = 0.9  # faces that meet at more than about 26 degrees make a sharp edge or corner (bevelled)
FAR = 1e9  # padding planes: n = 0, b = FAR, never the largest


@dataclass(frozen=True)
class ConvexPieces:
    """A mesh as convex pieces, in the mesh's own frame (its file's coordinates times its scale).

    Attributes:
        planes: (K, F, 4) float64, each piece's face planes (n_x, n_y, n_z, b): inside n . x <= b,
            n unit and outward; pieces with fewer faces are padded with (0, 0, 0, FAR).
        centres, radii: (K, 3), (K,) each piece's bounding sphere.
        vertices: each piece's hull vertices (V_k, 3).
        exact: the mesh is convex, and its one piece is its hull.
    """

    planes: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    vertices: tuple[np.ndarray, ...]
    exact: bool

    @property
    def n_pieces(self) -> int:
        return len(self.vertices)


def cache_dir() -> Path:
    """Where decompositions are cached: ``$GRASPNET_TORCH_CACHE``, else ``$XDG_CACHE_HOME`` or
    ``~/.cache``, then ``graspnet_torch``."""
    root = os.environ.get("GRASPNET_TORCH_CACHE")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "graspnet_torch"


def _planes(vertices: np.ndarray) -> np.ndarray:
    """(F, 4) the planes that bound the convex hull of points: its distinct faces (coplanar
    triangles merged), then bevel planes, at most ``MAX_PLANES`` in all.

    A bevel plane touches the hull along a sharp edge or at a sharp corner, its normal between
    those of the faces that meet there (the normalised sum of the two faces' normals, of the
    corner's faces' normals), its offset the hull's support value b = max_v n . v: it cuts nothing
    from the hull but lifts the max-plane distance beyond that edge or corner towards the true
    distance (a box's corner goes from up to sqrt(3) times too near to about 1.1 times). Bevels
    are added by farthest-point sampling of their directions against those already chosen.

    A hull of more faces than ``MAX_PLANES`` (a finely tessellated convex mesh: no sharp edges)
    is bounded instead by ``MAX_PLANES`` of its own faces, chosen greedily: its largest, then the
    face of the triangle whose centroid stands out farthest from the planes chosen so far. The
    polytope holds the hull and exceeds it least where it stands out most: on the README's capsule
    (r = 30 mm, 4096 triangles) its cylinder exactly, 0.25 mm at the median surface point and 1.8
    mm at the worst (on its caps). (Face directions spread evenly over the sphere and pushed out
    to the support values, before, bounded its cylinder mostly by planes tilted from it and pushed
    out along its length: 1.7-3.5 mm at the README's contacts on its side, 0.69 mm at the median
    surface point, 5.8 mm at the worst; the surface model's pads stopped 1-2 mm off those contacts.)"""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(vertices)
    eq = hull.equations  # (n, d): n . x + d <= 0 inside, n unit
    planes = np.concatenate([eq[:, :3], -eq[:, 3:]], axis=1)
    _, keep, which = np.unique(np.round(planes, 9), axis=0, return_index=True, return_inverse=True)
    faces = planes[keep]
    normals = faces[:, :3]
    which = which.ravel()
    if len(faces) > MAX_PLANES:  # the faces that bound the hull nearest: where it stands out most, its face
        tri = vertices[hull.simplices]
        area = np.bincount(which, np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1),
                           minlength=len(faces))  # each distinct face's area
        centroid = tri.mean(1)  # (n, 3): a point on each triangle, its face ``which``
        chosen = [int(np.argmax(area))]
        excess = faces[chosen[0], 3] - centroid @ normals[chosen[0]]  # how far each point lies inside the planes
        while len(chosen) < MAX_PLANES:
            worst = int(np.argmax(excess))
            if excess[worst] <= 1e-9:
                break
            face = int(which[worst])
            chosen.append(face)
            excess = np.minimum(excess, faces[face, 3] - centroid @ normals[face])
        return faces[chosen]
    # bevels: sharp edges (neighbouring triangles of two distinct faces) and corners
    candidates = []
    for t, neighbours in enumerate(hull.neighbors):
        for u in neighbours:
            a, b = which[t], which[u]
            if a < b and normals[a] @ normals[b] < BEVEL_COS:
                candidates.append(normals[a] + normals[b])
    incident: dict[int, set[int]] = {}
    for t, simplex in enumerate(hull.simplices):
        for v in simplex:
            incident.setdefault(int(v), set()).add(int(which[t]))
    for around in incident.values():
        if len(around) >= 3:
            m = normals[sorted(around)]
            if (m @ m.T).min() < BEVEL_COS:
                candidates.append(m.sum(0))
    if not candidates or len(faces) >= MAX_PLANES:
        return faces[np.argsort(keep)]
    directions = np.asarray(candidates)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    _, first = np.unique(np.round(directions, 9), axis=0, return_index=True)
    directions = directions[np.sort(first)]
    both = np.concatenate([normals, directions])
    chosen = _spread(both, list(range(len(faces))), min(MAX_PLANES, len(both)))
    bevels = both[chosen[len(faces):]]
    bevels = np.concatenate([bevels, (vertices @ bevels.T).max(0)[:, None]], axis=1)
    return np.concatenate([faces[np.argsort(keep)], bevels])


def _spread(directions: np.ndarray, chosen: list[int], count: int) -> list[int]:
    """Farthest-point sampling of unit directions: ``chosen`` then the farthest (in cosine) from
    every one chosen, until ``count``."""
    chosen = list(chosen)
    gap = (1.0 - directions @ directions[chosen].T).min(1)
    while len(chosen) < count:
        k = int(np.argmax(gap))
        if gap[k] <= 1e-9:
            break
        chosen.append(k)
        gap = np.minimum(gap, 1.0 - directions @ directions[k])
    return chosen


def _decompose(mesh) -> tuple[list[np.ndarray], bool]:
    """The hull vertices of each piece, and whether the mesh is convex (one exact piece): a mesh
    whose hull holds at most ``CONVEX_VOLUME_RATIO`` of its volume is its hull; any other is cut by
    CoACD with a shallow search (``COACD``; a closed mesh as it is, an open one after CoACD's
    remeshing) within ``COACD_BUDGET_S``, else (it ran past that, or failed) by planes
    (:func:`~graspnet_torch.collision.decompose.plane_pieces`). Where no piece spans a volume (a
    flat or broken mesh), the hull."""
    hull = mesh.convex_hull
    volume = abs(mesh.volume) if mesh.is_watertight else 0.0
    if mesh.is_convex or (volume > 0 and hull.volume <= CONVEX_VOLUME_RATIO * volume):
        return [np.asarray(hull.vertices, dtype=np.float64)], True
    vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    settings = {**COACD, "preprocess_mode": "off" if mesh.is_watertight else "on"}
    parts = coacd_apart(vertices, faces, settings, COACD_BUDGET_S)
    if parts is None:
        parts = plane_pieces(vertices, faces, mesh.is_watertight)
    out = [v for v in parts if len(v) >= 4 and np.linalg.matrix_rank(v - v.mean(0), tol=1e-9) == 3]
    if not out:
        return [np.asarray(hull.vertices, dtype=np.float64)], False
    return out, False


_COACD_WORKER = """
import json, sys
import numpy as np
import coacd
mesh = np.load(sys.argv[1])
coacd.set_log_level("error")
parts = coacd.run_coacd(coacd.Mesh(mesh["v"], mesh["f"]), **json.loads(sys.argv[3]))
np.savez(sys.argv[2], n=len(parts), **{f"v{k}": np.asarray(v, dtype=np.float64) for k, (v, _f) in enumerate(parts)})
"""


def coacd_apart(vertices: np.ndarray, faces: np.ndarray, settings: dict, timeout_s: float) -> list[np.ndarray] | None:
    """CoACD's pieces (their vertices (V_k, 3)) of a mesh (vertices (V, 3), faces (M, 3)) with
    ``settings`` (``coacd.run_coacd``'s keywords), run in a process of its own (on some meshes its
    C++ aborts, which would take this process with it). None where it did not finish within
    ``timeout_s`` or failed."""
    with tempfile.TemporaryDirectory() as folder:
        given, pieces = Path(folder) / "mesh.npz", Path(folder) / "pieces.npz"
        np.savez(given, v=vertices, f=faces)
        try:
            done = subprocess.run([sys.executable, "-c", _COACD_WORKER, str(given), str(pieces), json.dumps(settings)],
                                  capture_output=True, timeout=timeout_s, check=False)
        except subprocess.TimeoutExpired:
            return None
        if done.returncode != 0 or not pieces.is_file():
            return None
        with np.load(pieces) as data:
            return [data[f"v{k}"] for k in range(int(data["n"]))]


def convex_pieces(path: str | Path, scale: float = 1.0) -> ConvexPieces:
    """The convex pieces of a mesh file at a scale, from the cache (``cache_dir()/convex``, keyed
    by the file's bytes, the scale and the decomposition's settings) or computed and cached."""
    return _convex_pieces(mesh_path(path), float(scale))


@lru_cache(maxsize=32)
def _convex_pieces(path: Path, scale: float) -> ConvexPieces:
    settings = (scale, VERSION, sorted(COACD.items()), COACD_BUDGET_S, GRID, DEPTH, MAX_PIECES, MIN_CELLS)
    key = hashlib.sha256(path.read_bytes() + repr(settings).encode()).hexdigest()
    file = cache_dir() / "convex" / f"{key[:32]}.npz"
    if file.is_file():
        try:
            with np.load(file) as data:
                vertices = [data[f"v{k}"] for k in range(int(data["n"]))]
                return _pieces(vertices, bool(data["exact"]))
        except (OSError, ValueError, KeyError):  # a broken cache file: computed again below
            pass
    vertices, exact = _decompose(load_mesh(path, scale))
    try:
        with atomic_path(file, ".npz") as tmp:
            np.savez(tmp, n=len(vertices), exact=exact, **{f"v{k}": v for k, v in enumerate(vertices)})
    except OSError:  # a read-only cache: decompose again next time
        pass
    return _pieces(vertices, exact)


def _pieces(vertices: list[np.ndarray], exact: bool) -> ConvexPieces:
    planes = [_planes(v) for v in vertices]
    F = max(len(p) for p in planes)
    padded = np.zeros((len(planes), F, 4))
    padded[..., 3] = FAR
    for k, p in enumerate(planes):
        padded[k, : len(p)] = p
    lo = np.stack([v.min(0) for v in vertices])
    hi = np.stack([v.max(0) for v in vertices])
    centres = (lo + hi) / 2
    radii = np.array([np.linalg.norm(v - c, axis=1).max() for v, c in zip(vertices, centres, strict=True)])
    return ConvexPieces(padded, centres, radii, tuple(vertices), exact)


def pieces_distance(points: Tensor, planes: Tensor) -> Tensor:
    """Signed distance (lower bound outside) of points to convex pieces, batched.

    points: (..., K, 3) each point in its piece's frame; planes: (..., K, F, 4) -> (..., K):
    max_f (n_f . x - b_f).
    """
    return (torch.matmul(points.unsqueeze(-2), planes[..., :3].transpose(-1, -2)).squeeze(-2)
            - planes[..., 3]).amax(-1)


def piece_distance(points: Tensor, planes: Tensor) -> Tensor:
    """Signed distance (lower bound outside) of B sets of points to one piece each.

    points: (B, K, 3); planes: (B, F, 4) -> (B, K): max_f (n_f . x - b_f), one batched product.
    """
    return torch.baddbmm(-planes[:, None, :, 3], points, planes[..., :3].transpose(1, 2)).amax(-1)
