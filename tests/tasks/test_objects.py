"""Objects as users have them: real meshes from an installed package, problems moved anywhere,
primitives written as meshes, and contact sets closed on a mesh from a collision-free posture."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.mesh import mesh_query
from graspnet_torch.collision.problems import closure_problem
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import matrix_to_pose
from graspnet_torch.tasks.objects import REAL_OBJECTS, as_mesh, random_pose, real_objects
from graspnet_torch.tasks.problem import Shape


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPNET_TORCH_CACHE", str(tmp_path / "cache"))


def test_the_real_objects_come_from_an_installed_package_and_are_hand_sized():
    from graspnet_torch.meshes import load_mesh

    files = real_objects()
    assert set(files) == set(REAL_OBJECTS)
    for name, (path, scale) in files.items():
        assert path.is_file() and "site-packages" in str(path), name  # not a copy in this repository
        size = load_mesh(path.resolve(), scale).extents.max()
        assert 0.05 < size < 0.2, (name, size)


def test_random_poses_are_rigid_and_within_the_radius():
    rng = np.random.default_rng(0)
    for _ in range(50):
        T = random_pose(rng, 0.3)
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0) and np.linalg.norm(T[:3, 3]) <= 0.3


def test_a_moved_problem_moves_its_object_contacts_and_obstacles():
    problem = gt.GraspProblem.from_task("env1")  # arm_hand: object, contacts and three obstacles
    T = random_pose(np.random.default_rng(1))
    moved = problem.moved(T)
    np.testing.assert_allclose(moved.contacts_world(), problem.contacts_world() @ T[:3, :3].T + T[:3, 3], atol=1e-12)
    for a, b in zip(problem.obstacles, moved.obstacles, strict=True):
        np.testing.assert_allclose(b.trimesh().vertices, a.trimesh().vertices @ T[:3, :3].T + T[:3, 3], atol=1e-9)
    free = gt.GraspProblem.from_mapping({"robot": "hand", "contacts": [{"finger": "thumb", "position": [0, 0, 0]},
                                                                       {"finger": "index", "position": [0.05, 0, 0]}]})
    np.testing.assert_allclose(free.moved(T).contacts_world(), free.contacts_world() @ T[:3, :3].T + T[:3, 3])


def test_a_primitive_as_a_mesh_is_the_same_object(tmp_path):
    for task in ("glass3", "videotape5"):
        problem = gt.GraspProblem.from_task(task)
        meshed = as_mesh(problem, tmp_path)
        assert meshed.object.kind == "mesh" and meshed.object.mesh.suffix == ".stl"
        a, b = problem.object.trimesh(), meshed.object.trimesh()
        assert b.volume == pytest.approx(a.volume, rel=2e-3)
        np.testing.assert_allclose(b.bounds, a.bounds, atol=1e-6)


@pytest.mark.parametrize("name", ["blob000", "cylinder"])
def test_a_closure_contact_set_touches_the_mesh_from_a_collision_free_posture(hand, name):
    """Every contact lies on the surface (the fingertips closed until they touched it), and the
    reference posture puts each fingertip on its contact with no collision (FCL)."""
    path, scale = real_objects()[name]
    pose = matrix_to_pose(torch.as_tensor(random_pose(np.random.default_rng(3)))).numpy()
    problem = closure_problem(hand, Shape("mesh", (), pose, path, scale), seed=2, fingers=3)
    assert len(problem.contacts) == 3 and problem.fingers[0] == "thumb"
    query, T = mesh_query(problem.object)
    local = (problem.contacts_world() - T[:3, 3]) @ T[:3, :3]
    assert query.distance(local, 0.0).max() < 1e-5  # on the surface (a mesh that is not closed: its pieces)
    ref = problem.reference
    q = hand.home_posture().fingers.clone()
    for f, v in ref.joints.items():
        q[hand.finger_index(f)] = torch.as_tensor(v)
    posture = Posture(palm_pose=torch.as_tensor(ref.palm_pose), fingers=q, body=torch.zeros(0))
    tips = hand.fingertips_world(posture.palm_pose, q).numpy()
    for c, world in zip(problem.contacts, problem.contacts_world(), strict=True):
        assert np.linalg.norm(tips[hand.finger_index(c.finger)] - world) < 1e-9
    assert CollisionScene(hand, problem).count(posture) == 0
    again = closure_problem(hand, Shape("mesh", (), pose, path, scale), seed=2, fingers=3)
    np.testing.assert_array_equal(again.contacts_world(), problem.contacts_world())  # the same seed


@pytest.mark.slow
def test_the_solver_grasps_a_real_mesh_anywhere(hand):
    """A contact set on a real mesh at a random pose (its fingertip centres on the surface: the
    point model's contacts), default settings otherwise: success (within 1 mm, collision-free by
    FCL), and the result checks from the URDF alone."""
    path, scale = real_objects()["blob001"]
    pose = matrix_to_pose(torch.as_tensor(random_pose(np.random.default_rng(7)))).numpy()
    problem = closure_problem(hand, Shape("mesh", (), pose, path, scale), seed=0)
    result = gt.solve(problem, trials=20, seed=0, solver={"contact_model": "point"})
    assert result.success and result.failure is None
    best = result.best
    assert max(best.fingertip_error_mm.values()) <= 1.0 and best.collisions == 0
    from graspnet_torch.solver.api import trial_posture

    posture = trial_posture(hand, best)
    assert CollisionScene(hand, problem).count(posture) == 0
    tips = hand.fingertips_world(posture.palm_pose, posture.fingers).numpy()
    for c, world in zip(problem.contacts, problem.contacts_world(), strict=True):
        assert np.linalg.norm(tips[hand.finger_index(c.finger)] - world) * 1000 == pytest.approx(
            best.fingertip_error_mm[c.finger], abs=1e-6)


BOTTLE = """robot: hand
object:
  shape: mesh
  size: bottle.stl
  scale: 1.0
  pose: [0.0, 0.0, 0.2, {rx}, 0, 0]
contacts:
  - {{finger: thumb,  position: [0.03, 0.0, 0.0]}}
  - {{finger: index,  position: [-0.0282, 0.0102, 0.01]}}
  - {{finger: middle, position: [-0.0282, -0.0102, -0.01]}}
"""


@pytest.mark.slow
def test_the_readme_bottle_is_grasped_standing_and_lying(tmp_path):
    """The README's own-object example: a capsule exported as STL by trimesh, three contacts on its
    surface. Default settings (the surface model): standing and lying (rx = 90), each is a success
    (every pad within 1 mm of its contact and 30 degrees of the normal, nothing inside). The search
    turns with the bottle: in the point model the lying grasp is the standing one turned with it
    (the surface model then turns each grasp's pads in by a least-squares path that rounding can
    send elsewhere in a posture space with joints to spare: another grasp, as good)."""
    import math

    import trimesh

    from graspnet_torch.robot.transforms import pose_to_matrix

    trimesh.creation.capsule(height=0.1, radius=0.03).export(tmp_path / "bottle.stl")
    results = []
    for name, rx in (("standing", 0), ("lying", 90)):
        (tmp_path / f"{name}.yaml").write_text(BOTTLE.format(rx=rx))
        problem = gt.GraspProblem.from_file(tmp_path / f"{name}.yaml")
        result = gt.solve(problem, trials=20, seed=0)
        assert result.success and result.failure is None, result.failure
        best = result.best
        assert max(best.pad_distance_mm.values()) <= 1.0 and max(best.normal_angle_deg.values()) <= 30.0
        assert best.penetration_mm <= 1.0 and best.collisions == 0
        point = gt.solve(problem, trials=20, seed=0, solver={"contact_model": "point"})
        assert point.success and max(point.best.fingertip_error_mm.values()) <= 1.0 and point.best.collisions == 0
        results.append(point.best)

    def matrix(trial):
        return pose_to_matrix(torch.tensor(trial.palm_pose[:3] + [math.radians(a) for a in trial.palm_pose[3:]],
                                           dtype=torch.float64)).numpy()

    turn = np.eye(4)  # the bottle turned by 90 degrees about x around its centre (0, 0, 0.2)
    turn[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    turn[:3, 3] = np.array([0, 0, 0.2]) - turn[:3, :3] @ [0, 0, 0.2]
    np.testing.assert_allclose(matrix(results[1]), turn @ matrix(results[0]), atol=1e-4)
