"""Power grasps (the palm on the object, the fingers wrapped around it): independent re-checks of
what :func:`power_grasps` and :func:`gt.synthesize_grasps` return."""

from __future__ import annotations

import json
from functools import partial

import fcl
import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

import graspnet_torch as gt
from graspnet_torch.collision.geometry import fcl_geometry, fcl_transform, link_geometry
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.opposition import hand_axes
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.synthesis import power
from graspnet_torch.synthesis.autograsp import finger_spheres
from graspnet_torch.synthesis.closing import pad_forward
from graspnet_torch.synthesis.drafts import palm_front
from graspnet_torch.synthesis.opening import draw_open
from graspnet_torch.synthesis.power import power_grasps

SLACK_M = 1e-5  # FCL's distance against the search's points of the same surfaces


@pytest.fixture(scope="module")
def robot() -> gt.Robot:
    return gt.load_robot("hand")


def bottle() -> Shape:
    """A 5 x 18 cm cylinder, tilted: longer than the fingertips span around it."""
    return Shape("cylinder", (0.025, 0.18), np.array([0.0, 0.0, 0.2, 0.3, 0.2, 0.0]))


@pytest.fixture(scope="module")
def wraps(robot: gt.Robot) -> tuple[list, dict]:
    stats: dict = {}
    return power_grasps(robot, bottle(), 3, seed=0, max_tries=64, stats=stats), stats


def link_distances(robot: gt.Robot, obj: Shape, posture: gt.Posture) -> dict[str, float]:
    """Each link's distance (m) from the object: FCL between its collision shapes and the object's."""
    frames = robot.link_frames(posture)
    target = fcl.CollisionObject(fcl_geometry(obj.kind, obj.size), fcl_transform(pose_to_matrix_np(obj.pose)))
    out: dict[str, float] = {}
    for s in link_shapes(robot.urdf, "collision"):
        link = fcl.CollisionObject(link_geometry(s), fcl_transform(frames[s.link] @ s.origin))
        d = max(float(fcl.distance(link, target, fcl.DistanceRequest(), fcl.DistanceResult())), 0.0)
        out[s.link] = min(out.get(s.link, np.inf), d)
    return out


def test_links_touch_and_nothing_is_inside(robot: gt.Robot, wraps) -> None:
    grasps, stats = wraps
    assert len(grasps) == 3, stats
    obj = bottle()
    for g in grasps:
        posture = g.candidate.posture
        gaps = link_distances(robot, obj, posture)
        assert len(g.links) >= 2
        for link in g.links:  # every link said to touch lies within 1 mm of the object
            assert gaps[link] <= 1e-3 + SLACK_M, (link, gaps[link])
        # none deeper than 1 mm in it, no two fingers through each other: a fresh FCL scene
        report = CollisionScene(robot, g.problem, object_tolerance=0.001, touching=False,
                                fingers_apart=True).check(posture)
        assert report.count == 0, report


def test_contacts_are_on_the_surface_and_in_force_closure(wraps) -> None:
    grasps, _ = wraps
    obj = bottle()
    mesh = obj.trimesh()  # the object's surface as the search and MuJoCo take it (a primitive's triangulation)
    for g in grasps:
        _, distance, _ = trimesh.proximity.closest_point(mesh, g.contacts)
        assert np.all(distance <= 1e-6), distance
        q = gt.grasp_quality(g.contacts, g.candidate.normals, obj.pose[:3], 0.6)
        assert q.force_closure and g.quality.force_closure
        assert q.epsilon == pytest.approx(g.quality.epsilon, abs=1e-9)


def test_type_says_whether_more_than_pads_touch(robot: gt.Robot, wraps) -> None:
    grasps, _ = wraps
    pads = {p.link for p in robot.pads.values()}
    for g in grasps:
        assert g.type == ("power" if set(g.links) - pads else "precision")
    assert any(g.type == "power" and robot.cfg.palm_link in g.links for g in grasps)


def test_result_json_says_type_and_links(wraps) -> None:
    g = wraps[0][0]
    data = json.loads(json.dumps(g.to_dict()))
    assert data["type"] == g.type and data["links"] == list(g.links)
    assert data["normal_angles_deg"] == [None] * len(g.contacts)  # no pad aimed
    assert data["success"] and data["holds"] is None
    assert len(data["contacts"]) == len(set(data["contacts"][i]["finger"] for i in range(len(data["contacts"]))))


def test_synthesis_adds_power_grasps_where_pads_leave_too_few(robot: gt.Robot) -> None:
    pads_only = gt.synthesize_grasps(robot, bottle(), n_grasps=3, candidates=1, seed=0, power=False)
    both = gt.synthesize_grasps(robot, bottle(), n_grasps=3, candidates=1, seed=0)
    assert len(pads_only) <= 1 and {g.type for g in pads_only} <= {"precision"}
    assert len(both) == 3 and [g.type for g in both[: len(pads_only)]] == ["precision"] * len(pads_only)
    assert {g.type for g in both[len(pads_only):]} <= {"power", "precision"}
    assert any(g.type == "power" for g in both)
    for g in pads_only:
        assert g.links == tuple(dict.fromkeys(robot.pads[f].link for f in g.candidate.fingers))


def test_a_hand_without_a_palm_has_no_power_grasps() -> None:
    trifinger = gt.load_robot("examples/trifinger/trifinger.yaml")  # fingers hanging from a holder
    stats: dict = {}
    assert power_grasps(trifinger, bottle(), 1, stats=stats) == [] and stats == {}



def test_redrawn_open_fingers_let_the_palm_rest_nearer(robot: gt.Robot) -> None:
    """Palm poses facing a large ball, seated with their fingers open: where a finger keeps the palm
    off the ball, the redrawn open postures bring it nearer for some poses and farther for none
    (the ball's exact distance to the palm's surface points)."""
    ball = Shape("sphere", (0.045,), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    B, rng = 48, np.random.default_rng(0)
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    forward = pad_forward(robot, ((lo + hi) / 2)[None])[0]
    draw = partial(draw_open, forward, list(robot.fingers).index(hand_axes(robot).opposing), lo, hi, rng=rng)
    direction, q_open = draw(B)
    front = palm_front(robot, list(range(len(robot.fingers))))[0]
    T = np.repeat(np.eye(4)[None], B, axis=0)
    T[:, :3, :3] = Rotation.random(B, random_state=0).as_matrix()
    T[:, :3, 3] = ball.pose[:3] - 0.1 * T[:, :3, :3] @ front  # the palm's front toward the ball, 10 cm off
    palm, spheres, gap = power._palm_points(robot), finger_spheres(robot, surface=True, points=power.LINK_POINTS), \
        np.full(B, 0.0005)
    plain = power._palm_gap(ball, power._seated(robot, ball, T, torch.as_tensor(q_open), palm, front, spheres, gap),
                            palm)
    best = power._seated_best(robot, ball, T, (direction, q_open), draw, palm, front, spheres, gap)[0]
    redrawn = power._palm_gap(ball, best, palm)
    assert np.all(redrawn <= plain + 1e-9)
    assert np.sum(redrawn < plain - power.SEAT_TOL_M) >= 1, (plain, redrawn)
