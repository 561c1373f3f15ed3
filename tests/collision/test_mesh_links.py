"""Robots whose links are meshes: FCL (the engine of record) checks the mesh itself; the loop's
proxy covers it with spheres that hug it (collision/mesh_spheres.py), within its slack either way,
so it misses only what lies within that slack of the mesh."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.mesh_spheres import SLACK, SLACK_MIN_M
from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.collision.self_collision import self_collision_primitive
from graspnet_torch.collision.spheres import mesh_box, shape_spheres
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.transforms import pose_to_rt
from tests.mesh_robots import PALM_EXTENTS, mesh_hand_urdf, write_box_mesh, write_robot


@pytest.fixture(scope="module")
def mesh_hand(tmp_path_factory):
    """The two-finger hand whose palm is a box mesh (0.08 x 0.02 x 0.10 m) turned 30 degrees about
    z in the palm frame."""
    folder = tmp_path_factory.mktemp("meshhand")
    write_box_mesh(folder / "meshes" / "palm.stl")
    urdf = mesh_hand_urdf('<mesh filename="meshes/palm.stl"/>', rpy=(0.0, 0.0, np.pi / 6))
    return gt.load_robot(write_robot(folder, urdf))


def _problem(robot, obstacles):
    return gt.GraspProblem.from_mapping({
        "robot": robot.cfg.source, "obstacles": obstacles,
        "contacts": [{"finger": "thumb", "position": [0.0, 0.0, 0.12]},
                     {"finger": "index", "position": [0.0, 0.0, 0.12]}]}, source="mesh test", robot_cfg=robot.cfg)


def _box(centre, size=0.02):
    return {"shape": "box", "size": [size] * 3, "pose": [*centre, 0, 0, 0]}


def test_the_palm_mesh_is_a_link_shape(mesh_hand):
    palm = next(s for s in link_shapes(mesh_hand.urdf) if s.link == "palm")
    assert palm.kind == "mesh" and len(palm.mesh.faces) == 12
    np.testing.assert_allclose(palm.origin[:2, 0], [np.cos(np.pi / 6), np.sin(np.pi / 6)])
    np.testing.assert_allclose(palm.mesh.extents, PALM_EXTENTS, atol=1e-9)


def test_fcl_finds_a_box_crossing_the_mesh_and_not_one_beside_it(mesh_hand):
    home = mesh_hand.home_posture()
    near = CollisionScene(mesh_hand, _problem(mesh_hand, [_box([0.03, 0.0, 0.0])])).check(home)
    assert near.obstacle_pairs == [("palm", 0)] and near.count == 1
    far = CollisionScene(mesh_hand, _problem(mesh_hand, [_box([0.0, 0.045, -0.02])])).check(home)
    assert far.count == 0


def test_the_proxy_covers_the_mesh(mesh_hand):
    """Every point of the mesh's surface (points other than those the spheres were fitted to) lies
    within the slack of one of the proxy's spheres of the palm, and no sphere stands out of the box
    by more than the slack; its self-collision primitive is the grown box, which holds the mesh."""
    palm = next(s for s in link_shapes(mesh_hand.urdf) if s.link == "palm")
    centres, radii = shape_spheres(palm)
    import trimesh

    slack = max(SLACK_MIN_M, SLACK * min(PALM_EXTENTS)) * 1.05  # (of the extent along the points' least
    # principal axis, which sampling turns a few degrees off the box's: 20.5 mm, not 20)
    surface = trimesh.sample.sample_surface(palm.mesh, 4000, seed=0)[0]
    points = np.vstack([surface, palm.mesh.vertices]) @ palm.origin[:3, :3].T + palm.origin[:3, 3]
    gap = (np.linalg.norm(points[:, None] - centres[None], axis=-1) - radii).min(1)
    assert gap.max() < slack, gap.max()
    local = (centres - palm.origin[:3, 3]) @ palm.origin[:3, :3]  # back in the mesh's frame
    beyond = (np.abs(local) + radii[:, None] - np.asarray(PALM_EXTENTS) / 2).max()
    assert 0 < beyond <= slack + 1e-9, beyond
    box = mesh_box(palm)
    local = np.linalg.solve(box.origin, np.c_[points, np.ones(len(points))].T).T[:, :3]
    assert (np.abs(local) <= np.asarray(box.size) / 2 + 1e-9).all()
    assert self_collision_primitive(palm)[0] == "capsule"  # a small box: a capsule, as for box links


@pytest.mark.slow
def test_the_proxy_never_misses_what_fcl_finds_on_the_mesh(mesh_hand):
    """Random small boxes around the palm: each one FCL finds on the palm, the proxy finds too;
    boxes clear of the grown box are clear for both."""
    rng = np.random.default_rng(0)
    home = mesh_hand.home_posture()
    R, t = pose_to_rt(home.palm_pose.unsqueeze(0))
    fcl_hits = proxy_hits = 0
    for k in range(60):
        centre = rng.uniform([-0.07, -0.04, -0.07], [0.07, 0.04, 0.07])
        problem = _problem(mesh_hand, [_box(centre.tolist(), float(rng.uniform(0.005, 0.02)))])
        fcl = ("palm", 0) in CollisionScene(mesh_hand, problem).check(home).obstacle_pairs
        proxy = CollisionProxy(mesh_hand, problem, dtype=torch.float64)
        pairs = proxy.pairs((R, t), home.fingers.unsqueeze(0))[0]
        hit = bool(pairs[proxy.links.index("palm"), 0])
        assert hit or not fcl, (k, centre)
        fcl_hits += fcl
        proxy_hits += hit
    assert 10 <= fcl_hits <= proxy_hits < 60
