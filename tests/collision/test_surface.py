"""Object surfaces (graspnet_torch.collision.surface): outward normals and signed distances of
primitives (analytic) and meshes, moved and turned objects, and the tip targets of pads."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import graspnet_torch as gt
from graspnet_torch.collision.surface import (
    NEAR_ERROR_M,
    pad_targets,
    surface_distance,
    surface_distance_near,
    surface_distance_within,
    surface_normals,
    touch_points,
)
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np

POSE = np.array([0.1, -0.2, 0.3, 0.4, -0.7, 1.1])  # a moved and turned object (m, rad)


def _box_points(size, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points on a box's faces, away from its edges (local frame), and their outward normals."""
    half = np.asarray(size) / 2
    axis = rng.integers(0, 3, n)
    sign = rng.choice([-1.0, 1.0], n)
    p = rng.uniform(-0.5, 0.5, (n, 3)) * half
    p[np.arange(n), axis] = sign * half[axis]
    normals = np.zeros((n, 3))
    normals[np.arange(n), axis] = sign
    return p, normals


def _cylinder_points(r: float, h: float, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points on a cylinder's side and caps, away from the rims (local frame), and their normals."""
    theta = rng.uniform(0, 2 * np.pi, n)
    side = np.arange(n) % 2 == 0
    radial = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)], axis=1)
    rho = np.where(side, r, rng.uniform(0, 0.8 * r, n))
    z = np.where(side, rng.uniform(-0.4 * h, 0.4 * h, n), rng.choice([-h / 2, h / 2], n))
    p = radial * rho[:, None]
    p[:, 2] = z
    normals = np.where(side[:, None], radial, np.outer(np.sign(z), [0.0, 0.0, 1.0]))
    return p, normals


def _sphere_points(r: float, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return r * v, v


CASES = {
    "box": (Shape("box", (0.04, 0.06, 0.1), np.zeros(6)), lambda rng: _box_points((0.04, 0.06, 0.1), 200, rng)),
    "cylinder": (Shape("cylinder", (0.03, 0.12), np.zeros(6)), lambda rng: _cylinder_points(0.03, 0.12, 200, rng)),
    "sphere": (Shape("sphere", (0.025,), np.zeros(6)), lambda rng: _sphere_points(0.025, 200, rng)),
}


@pytest.mark.parametrize("kind", list(CASES))
def test_primitive_normals_and_distances_are_the_analytic_ones(kind):
    shape, sample = CASES[kind]
    points, normals = sample(np.random.default_rng(0))
    np.testing.assert_allclose(surface_normals(shape, points), normals, atol=1e-12)
    np.testing.assert_allclose(surface_distance(shape, points), 0.0, atol=1e-12)
    for d in (0.004, -0.002):  # off the surface along the normal: that distance, the same normal
        np.testing.assert_allclose(surface_distance(shape, points + d * normals), d, atol=1e-12)
        np.testing.assert_allclose(surface_normals(shape, points + d * normals), normals, atol=1e-12)


@pytest.mark.parametrize("kind", list(CASES))
def test_a_moved_and_turned_objects_normals_turn_with_it(kind):
    shape, sample = CASES[kind]
    points, normals = sample(np.random.default_rng(1))
    T = pose_to_matrix_np(POSE)
    moved = Shape(shape.kind, shape.size, POSE)
    world = points @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(surface_normals(moved, world), normals @ T[:3, :3].T, atol=1e-12)
    np.testing.assert_allclose(surface_distance(moved, world + 0.003 * normals @ T[:3, :3].T), 0.003, atol=1e-12)


def test_edges_and_corners_take_one_of_their_faces():
    box = Shape("box", (0.02, 0.02, 0.02), np.zeros(6))
    corner = surface_normals(box, np.array([[0.01, 0.01, 0.01]]))[0]
    assert sorted(np.abs(corner)) == [0.0, 0.0, 1.0] and corner.max() == 1.0
    cylinder = Shape("cylinder", (0.01, 0.04), np.zeros(6))
    rim = surface_normals(cylinder, np.array([[0.01, 0.0, 0.02], [0.0, 0.0, 0.0]]))
    assert np.linalg.norm(rim, axis=1) == pytest.approx([1.0, 1.0])
    # the centre of a cylinder taller than wide is nearest its side
    np.testing.assert_allclose(rim[1], [1.0, 0.0, 0.0])


def _mesh_file(tmp_path, mesh: trimesh.Trimesh, name: str) -> Shape:
    path = tmp_path / f"{name}.stl"
    mesh.export(path)
    return Shape("mesh", (), POSE, path, 1.0)


def test_a_mesh_boxs_normals_and_distances_agree_with_the_primitive(tmp_path):
    size = (0.04, 0.06, 0.1)
    mesh = _mesh_file(tmp_path, trimesh.creation.box(extents=size), "box")
    box = Shape("box", size, POSE)
    points, normals = _box_points(size, 100, np.random.default_rng(2))
    T = pose_to_matrix_np(POSE)
    world = points @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(surface_normals(mesh, world), surface_normals(box, world), atol=1e-9)
    for d in (0.003, -0.004):  # outside and inside: signed distances and normals still agree
        off = world + d * normals @ T[:3, :3].T
        np.testing.assert_allclose(surface_distance(mesh, off), d, atol=1e-9)
        np.testing.assert_allclose(surface_normals(mesh, off), surface_normals(box, off), atol=1e-9)


def test_a_mesh_spheres_normals_are_near_the_spheres(tmp_path):
    r = 0.03
    mesh = _mesh_file(tmp_path, trimesh.creation.icosphere(subdivisions=4, radius=r), "ball")
    sphere = Shape("sphere", (r,), POSE)
    points, _ = _sphere_points(r, 100, np.random.default_rng(3))
    T = pose_to_matrix_np(POSE)
    world = points @ T[:3, :3].T + T[:3, 3]
    cosine = (surface_normals(mesh, world) * surface_normals(sphere, world)).sum(axis=1)
    assert cosine.min() > np.cos(np.radians(5))  # facets of about 4 degrees
    np.testing.assert_allclose(surface_distance(mesh, world), 0.0, atol=2e-4)


def test_touch_points_of_a_mesh_box_are_the_primitives(tmp_path):
    """touch_points: a mesh box's nearest points and normals (trimesh's closest point) agree with
    the primitive box's exact ones, off the edges."""
    size = (0.04, 0.05, 0.06)
    mesh = _mesh_file(tmp_path, trimesh.creation.box(extents=size), "box")
    box = Shape("box", size, POSE)
    rng = np.random.default_rng(5)
    half = np.asarray(size) / 2
    local = rng.uniform(-1, 1, (300, 3)) * (half - 0.003)  # off the edges ...
    axis = rng.integers(0, 3, 300)
    rows = np.arange(300)
    local[rows, axis] = rng.choice([-1.0, 1.0], 300) * (half[axis] + rng.uniform(0.001, 0.01, 300))  # ... off a face
    T = pose_to_matrix_np(POSE)
    world = local @ T[:3, :3].T + T[:3, 3]
    c_mesh, n_mesh, off_mesh = touch_points(mesh, world)
    c_box, n_box, off_box = touch_points(box, world)
    np.testing.assert_allclose(c_mesh, c_box, atol=2e-5)
    np.testing.assert_allclose(n_mesh, n_box, atol=1e-9)
    assert off_mesh.max() == 0.0 and off_box.max() < 1e-9


def test_the_near_distance_is_within_its_bound_of_the_exact_one(tmp_path):
    """surface_distance_near on a mesh: within NEAR_ERROR_M of the exact distance near the surface,
    with its sign; farther out, on the right side and not below the exact distance by more than
    the bound; exact on primitives."""
    mesh = _mesh_file(tmp_path, trimesh.creation.capsule(height=0.05, radius=0.02, count=[12, 12]), "capsule")
    rng = np.random.default_rng(4)
    pts = POSE[:3] + rng.normal(0.0, 0.03, (400, 3))
    exact, near = surface_distance(mesh, pts), surface_distance_near(mesh, pts)
    close = np.abs(exact) < 0.005
    assert close.sum() > 20 and (~close).sum() > 20
    assert np.abs(near[close] - exact[close]).max() <= NEAR_ERROR_M
    assert np.abs(near[close] - exact[close]).max() > 1e-6  # an approximation, measured as one
    assert np.all(np.sign(near[~close]) == np.sign(exact[~close]))
    assert np.all(np.abs(near[~close]) >= np.abs(exact[~close]) - NEAR_ERROR_M)
    box = Shape("box", (0.04, 0.05, 0.06), POSE)
    np.testing.assert_array_equal(surface_distance_near(box, pts), surface_distance(box, pts))


def test_the_distance_within_a_bound_is_exact_there_and_over_it_elsewhere(tmp_path):
    """surface_distance_within on a mesh: the exact distance wherever that is within the bound,
    a value over the bound everywhere else (points spread from inside to 3 cm out)."""
    mesh = _mesh_file(tmp_path, trimesh.creation.capsule(height=0.05, radius=0.02, count=[12, 12]), "capsule")
    pts = POSE[:3] + np.random.default_rng(5).normal(0.0, 0.03, (400, 3))
    exact, within = surface_distance(mesh, pts), surface_distance_within(mesh, pts, 0.002)
    inside = exact <= 0.002
    assert inside.sum() > 20 and (~inside).sum() > 20
    np.testing.assert_array_equal(within[inside], exact[inside])
    assert (within[~inside] > 0.002).all()


@pytest.mark.parametrize("task", ["glass3", "glass4"])
def test_pad_targets_lie_outside_the_object_by_the_pad_depth(robots, task):
    robot = robots["hand"]
    problem = gt.GraspProblem.from_task(task)
    targets = pad_targets(robot, problem)
    contacts = problem.contacts_world()
    depth = np.array([robot.pads[f].depth for f in problem.fingers])
    assert targets.shape == contacts.shape
    np.testing.assert_allclose(surface_distance(problem.object, contacts), 0.0, atol=1e-5)  # contacts on the glass
    np.testing.assert_allclose(surface_distance(problem.object, targets), depth, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(targets - contacts, axis=1), depth, atol=1e-12)
    np.testing.assert_allclose(depth[:2], [0.008075, 0.007225])  # thumb, index


def test_pad_targets_follow_a_moved_problem(robots):
    robot = robots["hand"]
    problem = gt.GraspProblem.from_task("glass3")
    T = pose_to_matrix_np(POSE)
    moved = problem.moved(T)
    np.testing.assert_allclose(pad_targets(robot, moved), pad_targets(robot, problem) @ T[:3, :3].T + T[:3, 3],
                               atol=1e-12)


def test_pad_targets_need_an_object(robots):
    problem = gt.GraspProblem.from_task("glass3")
    bare = gt.GraspProblem(problem.robot, problem.contacts, source="bare.yaml")
    with pytest.raises(gt.ProblemError, match=r"bare\.yaml: the surface contact model needs the problem's object"):
        pad_targets(robots["hand"], bare)
