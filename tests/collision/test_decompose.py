"""The plane decomposition: convex pieces that hold a mesh's solid and leave its concavities out."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import Delaunay

from graspnet_torch.collision.decompose import MAX_PIECES, plane_pieces
from graspnet_torch.collision.mesh import MeshQuery, point_triangle_distance


def _l_prism() -> trimesh.Trimesh:
    """An L, 60 x 60 mm with 20 mm arms, 20 mm thick: closed, its notch 40 x 40 mm."""
    square = [(0, 0), (60, 0), (60, 20), (20, 20), (20, 60), (0, 60)]
    faces = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]
    return trimesh.creation.extrude_triangulation(np.asarray(square, float) / 1000, np.asarray(faces), 0.02)


def _inside_pieces(pieces: list[np.ndarray], points: np.ndarray) -> np.ndarray:
    """(n,) whether each point lies in some piece (the hull of its vertices)."""
    out = np.zeros(len(points), dtype=bool)
    for v in pieces:
        out |= Delaunay(v).find_simplex(points) >= 0
    return out


def _verdicts(mesh: trimesh.Trimesh, pieces: list[np.ndarray], margin: float, n: int = 4000
              ) -> tuple[float, float]:
    """Of points drawn in the mesh's box: the share of those deeper than ``margin`` inside the mesh
    that the pieces hold, and of those farther than ``margin`` outside that they leave out."""
    lo, hi = mesh.bounds
    points = lo + (hi - lo) * np.random.default_rng(0).uniform(size=(n, 3))
    depth = point_triangle_distance(points, np.asarray(mesh.triangles)).min(1)
    inside = MeshQuery(mesh).inside(points)
    held = _inside_pieces(pieces, points)
    deep, far = inside & (depth > margin), ~inside & (depth > margin)
    return float(held[deep].mean()), float(1.0 - held[far].mean())


def test_an_l_is_cut_at_its_corner_and_its_notch_left_out() -> None:
    mesh = _l_prism()
    pieces = plane_pieces(mesh.vertices, mesh.faces, closed=True)
    assert 2 <= len(pieces) <= MAX_PIECES
    held, left_out = _verdicts(mesh, pieces, 0.002)
    assert held == 1.0 and left_out == 1.0, (held, left_out)  # its hull would hold the notch: 4/9 of its box
    for v in pieces:  # every piece within the mesh's box
        assert np.all(v >= mesh.bounds[0] - 1e-9) and np.all(v <= mesh.bounds[1] + 1e-9)


def test_a_ring_keeps_its_hole_open() -> None:
    mesh = trimesh.creation.torus(major_radius=0.03, minor_radius=0.01)
    pieces = plane_pieces(mesh.vertices, mesh.faces, closed=True)
    held, left_out = _verdicts(mesh, pieces, 0.0015)
    assert held == 1.0 and left_out > 0.99, (held, left_out)
    assert not _inside_pieces(pieces, np.zeros((1, 3)))[0]  # the hole's centre


def test_an_open_box_is_walls_and_a_floor_not_a_block() -> None:
    """A box without its top (not closed): the pieces hold its walls, not the space they enclose,
    which is open to the outside."""
    box = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    top = box.face_normals[:, 2] > 0.5
    mesh = trimesh.Trimesh(box.vertices, box.faces[~top], process=False)
    assert not mesh.is_watertight
    pieces = plane_pieces(mesh.vertices, mesh.faces, closed=False)
    assert len(pieces) >= 2
    inside = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.012], [0.01, -0.01, 0.0]])
    assert not _inside_pieces(pieces, inside).any()
    surface = trimesh.sample.sample_surface(mesh, 500, seed=0)[0] * 0.999  # just inside the walls' outer faces
    assert _inside_pieces(pieces, surface).mean() > 0.99


def test_the_pieces_are_the_same_each_call() -> None:
    mesh = _l_prism()
    first = plane_pieces(mesh.vertices, mesh.faces, closed=True)
    again = plane_pieces(mesh.vertices, mesh.faces, closed=True)
    assert len(first) == len(again) and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
