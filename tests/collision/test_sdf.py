"""A mesh's signed distance grid (graspnet_torch.collision.sdf) against exact answers: a box
mesh's distance (analytic) and inside (its extents), also where its faces lie on grid lines."""

from __future__ import annotations

import warnings

import numpy as np
import trimesh

from graspnet_torch.collision.mesh import closest_points, mesh_query
from graspnet_torch.collision.sdf import BAND_M, CELL_M, MAX_CELLS, distance_grid
from graspnet_torch.robot.shape import Shape


def _box(tmp_path, extents) -> Shape:
    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=extents).export(path)
    return Shape("mesh", (), np.zeros(6), path, 1.0)


def _box_distance(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def test_a_box_meshs_grid_is_exact_off_its_faces_and_near_everywhere(tmp_path):
    half = np.array([0.02, 0.03, 0.015])
    grid = distance_grid(_box(tmp_path, 2 * half))
    rng = np.random.default_rng(0)
    face = rng.uniform(-0.6, 0.6, (300, 3)) * half  # over a face's middle, off it by up to 2 mm
    axis = rng.integers(0, 3, 300)
    face[np.arange(300), axis] = rng.choice([-1.0, 1.0], 300) * half[axis] + rng.uniform(-0.002, 0.002, 300)
    np.testing.assert_allclose(grid(face), _box_distance(face, half), atol=1e-8)  # (an STL: float32)
    anywhere = rng.uniform(-1.5, 1.5, (2000, 3)) * half
    exact = _box_distance(anywhere, half)
    err = np.abs(grid(anywhere) - exact)
    near = np.abs(exact) < BAND_M  # exact values around: off only at the edges and corners
    assert err[near].max() < CELL_M / 3 and err.max() < CELL_M
    clear = np.abs(exact) > CELL_M / 3  # farther from the surface than the error: the right side
    assert np.all(np.sign(grid(anywhere[clear])) == np.sign(exact[clear]))


def test_the_grid_sign_is_right_where_the_faces_lie_on_grid_points(tmp_path):
    """Extents of whole cells put every face on grid points and every edge on grid lines (the
    inside test's columns would meet them; they are moved off): every grid point's sign matches
    the box's, the points near the faces hold the exact distance (on a face: zero)."""
    half = CELL_M * np.array([10.0, 14.0, 8.0])
    grid = distance_grid(_box(tmp_path, 2 * half))
    axes = [grid.origin[d] + grid.cell * np.arange(grid.values.shape[d]) for d in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    exact = _box_distance(points, half)
    values = grid.values.ravel()
    off = np.abs(exact) > 1e-8
    assert np.all(np.sign(values[off]) == np.sign(exact[off]))
    band = np.abs(exact) < BAND_M  # exact there; farther out an upper bound
    np.testing.assert_allclose(values[band], exact[band], atol=1e-8)
    assert np.all(np.abs(values) >= np.abs(exact) - 1e-8)


def test_a_large_meshs_grid_grows_its_cells_and_stays_exact_near_its_faces(tmp_path):
    """A 1 m box: at most MAX_CELLS grid points (at 1.5 mm it would be 333 million), cells grown
    to fit, and still exact near its faces and right in sign away from them."""
    half = np.array([0.5, 0.5, 0.5])
    grid = distance_grid(_box(tmp_path, 2 * half))
    assert grid.values.size <= MAX_CELLS and grid.cell > CELL_M
    rng = np.random.default_rng(1)
    face = rng.uniform(-0.6, 0.6, (300, 3)) * half
    axis = rng.integers(0, 3, 300)
    face[np.arange(300), axis] = rng.choice([-1.0, 1.0], 300) * half[axis] + rng.uniform(-0.002, 0.002, 300)
    np.testing.assert_allclose(grid(face), _box_distance(face, half), atol=1e-7)
    anywhere = rng.uniform(-1.2, 1.2, (2000, 3)) * half
    exact = _box_distance(anywhere, half)
    clear = np.abs(exact) > grid.cell
    assert np.all(np.sign(grid(anywhere[clear])) == np.sign(exact[clear]))


def test_an_open_meshs_grid_takes_its_sign_from_the_meshs_own_inside_test(tmp_path):
    """A box without its top (not closed: its inside is its convex pieces'): every grid
    point's sign is the mesh's own inside test (each piece tested in its box only), the points near
    its faces hold the exact distance."""
    half = np.array([0.02, 0.015, 0.01])
    box = trimesh.creation.box(extents=2 * half)
    box.update_faces(box.face_normals[:, 2] < 0.5)  # the top's two triangles gone
    path = tmp_path / "open_box.stl"
    box.export(path)
    obj = Shape("mesh", (), np.zeros(6), path, 1.0)
    query = mesh_query(obj)[0]
    assert not query.closed and query.pieces is not None
    grid = distance_grid(obj)
    axes = [grid.origin[d] + grid.cell * np.arange(grid.values.shape[d]) for d in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = query.inside(points)
    assert inside.any() and np.array_equal(grid.values.ravel() < 0, inside)
    sides = np.abs(_box_distance(points, half)) < BAND_M
    sides &= points[:, 2] < half[2] - BAND_M  # away from the missing top
    exact = np.abs(_box_distance(points[sides], half))
    np.testing.assert_allclose(np.abs(grid.values.ravel()[sides]), exact, atol=1e-8)


def test_a_point_beyond_the_grid_reads_its_nearest_grid_point_plus_the_way_there(tmp_path):
    """Beyond the grid (20 mm around the mesh's box) a distance is the value at the nearest grid
    point plus the distance to it: an upper bound of the exact one, never below it; a point within
    the grid reads the same value alone as in a batch that has points beyond it."""
    half = np.array([0.02, 0.03, 0.015])
    grid = distance_grid(_box(tmp_path, 2 * half))
    rng = np.random.default_rng(2)
    far = rng.normal(size=(200, 3))
    far *= (0.1 / np.linalg.norm(far, axis=1))[:, None]  # 10 cm from the centre: beyond the grid
    top = grid.origin + grid.cell * (np.array(grid.values.shape) - 1)
    assert np.any((far < grid.origin) | (far > top), axis=1).all()
    exact = _box_distance(far, half)
    beyond = grid(far)
    assert np.all(beyond >= exact - 1e-8) and np.all(beyond <= exact + 0.02)
    clamped = np.clip(far, grid.origin, top)
    np.testing.assert_allclose(beyond, grid(clamped) + np.linalg.norm(far - clamped, axis=1), atol=1e-12)
    near = rng.uniform(-1.2, 1.2, (50, 3)) * half
    np.testing.assert_array_equal(grid(np.concatenate([near, far]))[:50], grid(near))


def test_nearly_flat_triangles_give_a_finite_point_without_a_warning():
    """Triangles whose corners are collinear to round-off (a mesh's slivers): a finite point, with no
    numpy warning on stderr ('invalid value encountered in add' before)."""
    rng = np.random.default_rng(0)
    n = 20000
    a, d, p = rng.uniform(-0.05, 0.05, (n, 3)), rng.uniform(-0.01, 0.01, (n, 3)), rng.uniform(-0.05, 0.05, (n, 3))
    s = rng.uniform(-2, 3, n)  # c = a + s d: on the line through a and b = a + d
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = closest_points(p, a, a + d, a + s[:, None] * d)
    assert np.isfinite(got).all()
