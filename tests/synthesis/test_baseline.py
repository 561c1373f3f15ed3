"""The approach-and-close baseline planner: independent re-checks of what it returns."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.geometry import fcl_geometry, fcl_transform, link_geometry
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.errors import ProblemError
from graspnet_torch.physics import DIRECTIONS
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.baseline import MIN_TOUCHING, baseline_grasps

SLACK_M = 2e-4  # the planner's link model (spheres and rim points) against FCL's exact shapes


@pytest.fixture(scope="module")
def robot() -> gt.Robot:
    return gt.load_robot("hand")


def cube() -> Shape:
    return Shape("box", (0.06, 0.06, 0.06), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))


def sphere() -> Shape:
    return Shape("sphere", (0.04,), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))


def finger_links(robot: gt.Robot) -> dict[str, set[str]]:
    """Each finger's links, from its base to its tip."""
    return {name: {j.child for j in robot.urdf.path_joints(f.chain.root, f.chain.tip)}
            for name, f in robot.fingers.items()}


def finger_gaps(robot: gt.Robot, obj: Shape, posture: gt.Posture) -> dict[str, float]:
    """Each finger's least distance (m) from the object (a primitive): FCL's distance between its
    links' collision shapes (placed by the URDF link frames) and the object (0 where they meet)."""
    import fcl

    frames = robot.link_frames(posture)
    owner = {link: f for f, links in finger_links(robot).items() for link in links}
    target = fcl.CollisionObject(fcl_geometry(obj.kind, obj.size), fcl_transform(pose_to_matrix_np(obj.pose)))
    out = dict.fromkeys(robot.fingers, np.inf)
    for s in link_shapes(robot.urdf, "collision"):
        if s.link in owner:
            link = fcl.CollisionObject(link_geometry(s), fcl_transform(frames[s.link] @ s.origin))
            d = fcl.distance(link, target, fcl.DistanceRequest(), fcl.DistanceResult())
            out[owner[s.link]] = min(out[owner[s.link]], max(float(d), 0.0))
    return out


@pytest.fixture(scope="module")
def cube_grasps(robot: gt.Robot) -> list:
    stats: dict = {}
    grasps = baseline_grasps(robot, cube(), n_grasps=6, candidates=32, seed=0, stats=stats)
    return grasps, stats


@pytest.mark.parametrize("obj", [cube(), sphere()], ids=["box", "sphere"])
def test_grasps_touch_and_do_not_penetrate(robot: gt.Robot, obj: Shape) -> None:
    grasps = baseline_grasps(robot, obj, n_grasps=6, candidates=32, seed=1)
    assert grasps, "no grasp from 32 palm poses"
    for g in grasps:
        assert len(g.touching) >= MIN_TOUCHING and g.touching[0] == "thumb"
        assert g.problem.fingers == g.touching
        gaps = finger_gaps(robot, obj, g.posture)
        for f in g.touching:  # a link of every touching finger on the surface
            assert gaps[f] <= 1e-3 + SLACK_M, (f, gaps[f])
        for f in set(robot.fingers) - set(g.touching):  # the others clear of it
            assert gaps[f] > 1e-3 - SLACK_M, (f, gaps[f])
        # none deeper than 1 mm in it, no two fingers through each other: a fresh FCL scene
        scene = CollisionScene(robot, g.problem, object_tolerance=0.001, touching=False, fingers_apart=True)
        report = scene.check(g.posture)
        assert report.count == 0, report
    assert [len(g.touching) for g in grasps] == sorted((len(g.touching) for g in grasps), reverse=True)


def test_result_is_the_posture_and_a_squeeze(robot: gt.Robot, cube_grasps) -> None:
    grasps, _ = cube_grasps
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    for g in grasps:
        start = trial_posture(robot, g.result.best)
        assert torch.allclose(start.palm_pose, g.posture.palm_pose, atol=1e-9)
        assert torch.allclose(start.fingers, g.posture.fingers, atol=1e-9)
        squeeze = trial_posture(robot, g.result.best.fields["squeeze"])
        assert torch.equal(squeeze.palm_pose, start.palm_pose)
        assert torch.all(squeeze.fingers >= lo - 1e-9) and torch.all(squeeze.fingers <= hi + 1e-9)
        moved = (squeeze.fingers - start.fingers).abs()
        assert moved.max() > 0.0 and moved.max() <= np.radians(5.0) + 1e-9
        assert g.result.success and g.result.robot == robot.cfg.name and g.holds is None


def test_stats(cube_grasps) -> None:
    grasps, stats = cube_grasps
    assert stats["tried"] == 32 and stats["tried"] >= stats["touching"] >= stats["clean"] >= len(grasps)
    assert stats["checked"] == 0 and all(stats[k] >= 0 for k in ("close_s", "check_s", "physics_s"))


def test_deterministic_for_a_seed(robot: gt.Robot, cube_grasps) -> None:
    grasps, _ = cube_grasps
    again = baseline_grasps(robot, cube(), n_grasps=6, candidates=32, seed=0)
    other = baseline_grasps(robot, cube(), n_grasps=6, candidates=32, seed=3)
    assert [g.touching for g in again] == [g.touching for g in grasps]
    for a, b in zip(again, grasps, strict=True):
        assert torch.equal(a.posture.palm_pose, b.posture.palm_pose)
        assert torch.equal(a.posture.fingers, b.posture.fingers)
        assert a.result.to_dict() == b.result.to_dict()
    assert not torch.equal(other[0].posture.palm_pose, grasps[0].posture.palm_pose)


def test_physics_reports(robot: gt.Robot) -> None:
    stats: dict = {}
    grasps = baseline_grasps(robot, cube(), n_grasps=5, candidates=32, seed=0, physics=gt.simulate_grasp,
                             stats=stats)
    assert grasps and stats["checked"] == stats["clean"]
    assert sum(g.holds == 6 for g in grasps) <= stats["held"] <= stats["checked"]
    assert 0 <= stats["held_physics_s"] <= stats["physics_s"] and (stats["held_physics_s"] > 0) == (stats["held"] > 0)
    for g in grasps:
        assert set(g.physics.directions) == set(DIRECTIONS) and 0 <= g.holds <= 6
    ranks = [(len(g.touching), g.holds) for g in grasps]
    assert ranks == sorted(ranks, reverse=True)


def test_refuses(robot: gt.Robot) -> None:
    with pytest.raises(ProblemError):
        baseline_grasps(robot, cube(), n_grasps=0)
    with pytest.raises(ProblemError):
        baseline_grasps(robot, cube(), candidates=0)
