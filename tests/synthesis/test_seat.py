"""Pads seated on the surface: a precision grasp's pad links touch the object (FCL), for a hand
whose mesh fingertips are not spheres about their tip frames (Allegro)."""

from __future__ import annotations

import fcl
import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.geometry import fcl_geometry, fcl_transform, link_geometry
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.seat import SEATED_M, move_tips

ALLEGRO = repo_root() / "examples/allegro_hand/allegro_hand_right.yaml"


@pytest.fixture(scope="module")
def allegro() -> gt.Robot:
    return gt.load_robot(ALLEGRO)


def marker() -> Shape:
    """A 1.5 x 13 cm cylinder lying tilted: the pads meet it at their cone's edge."""
    return Shape("cylinder", (0.0075, 0.13), np.array([0.0, 0.0, 0.2, 0.0, 1.4, 0.3]))


def fcl_gap(robot: gt.Robot, obj: Shape, posture: Posture, link: str) -> float:
    """A link's distance (m) from the object: FCL between its collision shapes and the object's."""
    frames = robot.link_frames(posture)
    target = fcl.CollisionObject(fcl_geometry(obj.kind, obj.size), fcl_transform(pose_to_matrix_np(obj.pose)))
    gaps = [fcl.distance(fcl.CollisionObject(link_geometry(s), fcl_transform(frames[s.link] @ s.origin)), target,
                         fcl.DistanceRequest(), fcl.DistanceResult())
            for s in link_shapes(robot.urdf, "collision") if s.link == link]
    return max(min(gaps), 0.0)


def test_precision_pads_touch_the_object(allegro: gt.Robot) -> None:
    obj, stats = marker(), {}
    grasps = gt.synthesize_grasps(allegro, obj, n_grasps=2, candidates=8, seed=0, power=False, stats=stats)
    assert grasps, stats
    for g in grasps:
        posture = trial_posture(allegro, g.result.best)
        assert g.type == "precision" and len(g.links) == 3
        for link in g.links:  # each pad link said to touch lies within 1 mm of the object
            assert fcl_gap(allegro, obj, posture, link) <= SEATED_M, link


def test_move_tips_moves_each_tip_as_asked(allegro: gt.Robot) -> None:
    lower, upper = allegro.finger_limits
    posture = Posture(palm_pose=torch.tensor([0.1, 0.0, 0.2, 0.4, -0.3, 1.0], dtype=torch.float64),
                      fingers=torch.as_tensor(lower + 0.4 * (upper - lower)), body=allegro.home_posture().body)
    moves = np.array([[0.0015, -0.001, 0.0005], [0.0, 0.0, -0.002]])
    moved = move_tips(allegro, posture, [0, 2], moves)
    R = pose_to_matrix_np(posture.palm_pose.numpy())[:3, :3]
    before = allegro.fingertips_palm(posture.fingers[None])[0].numpy()
    after = allegro.fingertips_palm(moved.fingers[None])[0].numpy()
    assert np.allclose((after - before)[[0, 2]] @ R.T, moves, atol=5e-5)
    assert np.allclose(after[[1, 3]], before[[1, 3]])  # the other fingers kept
    assert bool((moved.palm_pose == posture.palm_pose).all())

