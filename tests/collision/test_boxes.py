"""The collision scene's broad phase (collision/boxes.py): oriented boxes around every shape and
the separating-axis test. It may only let pairs through, never drop one that collides."""

from __future__ import annotations

import fcl
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene, environment_obstacles
from graspnet_torch.collision.boxes import boxes_apart, link_box
from graspnet_torch.collision.geometry import fcl_geometry, link_geometry
from graspnet_torch.robot.geometry import LinkShape, link_shapes
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import pose_to_matrix_np, rt_to_pose


def _box(T: np.ndarray, half: np.ndarray):
    return fcl.CollisionObject(fcl.Box(*(2 * half)), fcl.Transform(T[:3, :3], T[:3, 3]))


def test_separating_axes_agree_with_fcl_on_random_boxes():
    rng = np.random.default_rng(0)
    n = 3000
    T = np.tile(np.eye(4), (2, n, 1, 1))
    T[:, :, :3, :3] = Rotation.random(2 * n, random_state=1).as_matrix().reshape(2, n, 3, 3)
    T[:, :, :3, 3] = rng.uniform(-1, 1, (2, n, 3))
    half = rng.uniform(0.05, 0.6, (2, n, 3))
    apart = boxes_apart(T[0], half[0], T[1], half[1], margin=0.0)
    meet = np.array([fcl.collide(_box(T[0, k], half[0, k]), _box(T[1, k], half[1, k]), fcl.CollisionRequest(),
                                 fcl.CollisionResult()) for k in range(n)], dtype=bool)
    assert 0.1 < meet.mean() < 0.9
    assert np.array_equal(apart, ~meet)


def test_the_margin_makes_near_boxes_meet():
    T0, T1 = np.eye(4), np.eye(4)
    T1[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    h = np.full(3, 0.1)
    reach = 0.1 + 0.1 * (np.cos(np.radians(30)) + np.sin(np.radians(30)))  # B's extent along x
    T1[0, 3] = reach + 5e-4  # 0.5 mm apart
    assert boxes_apart(T0, h, T1, h, margin=0.0)
    assert not boxes_apart(T0, h, T1, h, margin=1e-3)


@pytest.mark.parametrize("kind, size", [("box", (0.1, 0.04, 0.2)), ("cylinder", (0.03, 0.2)), ("sphere", (0.05,))])
def test_a_shape_lies_inside_its_box(kind, size):
    """Points of the shape's surface (FCL's own geometry, sampled by distance queries) lie in its box."""
    origin = np.eye(4)
    origin[:3, :3] = Rotation.from_euler("xyz", [20, -40, 70], degrees=True).as_matrix()
    origin[:3, 3] = [0.1, -0.2, 0.3]
    shape = LinkShape.placed("link", kind, size, origin)
    T, half = link_box(shape)
    obj = fcl.CollisionObject(link_geometry(shape), fcl.Transform(origin[:3, :3], origin[:3, 3]))
    rng = np.random.default_rng(0)
    for direction in rng.normal(size=(200, 3)):  # a tiny sphere just outside the box never touches the shape
        direction /= np.linalg.norm(direction)
        local = direction / np.max(np.abs(direction) / half) * 1.001  # on the box's surface, pushed out
        point = T[:3, :3] @ local + T[:3, 3]
        probe = fcl.CollisionObject(fcl.Sphere(1e-5), fcl.Transform(np.eye(3), point))
        assert not fcl.collide(obj, probe, fcl.CollisionRequest(), fcl.CollisionResult())


def _direct(robot, problem, posture):
    """Every (link, obstacle) pair and every self-collision pair tested by FCL directly, no broad phase."""
    from graspnet_torch.collision import self_collision_pairs

    frames = robot.link_frames(posture)
    objects = {}
    for s in link_shapes(robot.urdf, "collision"):
        T = frames[s.link] @ s.origin
        objects.setdefault(s.link, []).append(fcl.CollisionObject(link_geometry(s), fcl.Transform(T[:3, :3], T[:3, 3])))
    obstacles = []
    for o in environment_obstacles(robot, problem):
        T = pose_to_matrix_np(o.pose)
        obstacles.append(fcl.CollisionObject(fcl_geometry(o.kind, o.size), fcl.Transform(T[:3, :3], T[:3, 3])))

    def hit(xs, ys):
        return any(fcl.collide(x, y, fcl.CollisionRequest(), fcl.CollisionResult()) for x in xs for y in ys)

    pairs = sorted((link, k) for link in objects for k, o in enumerate(obstacles) if hit(objects[link], [o]))
    own = sorted((a, b) for a, b in self_collision_pairs(robot) if hit(objects[a], objects[b]))
    return pairs, own


@pytest.mark.parametrize("robot_name, task", [("arm_hand", "env1"), ("manus", "cube")])
def test_the_broad_phase_drops_no_collision(robot_name, task):
    """On random configurations, the scene's obstacle and self-collision pairs are exactly those
    FCL finds testing every pair directly, and collides_many says which postures collide."""
    robot = gt.load_robot(robot_name)
    problem = gt.GraspProblem.from_task(task)
    scene = CollisionScene(robot, problem, touching=False)
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    g = torch.Generator().manual_seed(5)
    postures = []
    for _ in range(60):
        body = lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)
        fingers = flo + (fhi - flo) * torch.rand(flo.shape, generator=g, dtype=torch.float64)
        postures.append(Posture(rt_to_pose(*robot.palm_frame(body)), fingers, body))
    reports = scene.check_many(postures)
    colliding = 0
    for posture, report in zip(postures, reports, strict=True):
        pairs, own = _direct(robot, problem, posture)
        assert report.obstacle_pairs == pairs
        assert sorted(report.self_pairs) == own
        colliding += bool(pairs or own)
    print(f"{colliding} of 60 collide")
    assert 5 < colliding < 60
    assert np.array_equal(scene.collides_many(postures), np.array([r.count > 0 for r in reports]))
