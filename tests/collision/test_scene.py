"""FCL collision counts against closed-form geometry (sphere obstacles vs box, cylinder and sphere
links), and the object-penetration rule of INTERFACE.md."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture


def _reference_posture(robot, problem) -> Posture:
    home = robot.home_posture()
    q = home.fingers.clone()
    for f, v in problem.reference.joints.items():
        q[robot.finger_index(f)] = torch.as_tensor(v)
    return Posture(palm_pose=torch.as_tensor(problem.reference.palm_pose), fingers=q, body=home.body)


def _sphere_hits(shape, T_link: np.ndarray, centre: np.ndarray, radius: float) -> bool:
    """Closed form: does a sphere intersect a link primitive placed at T_link @ shape.origin?"""
    T = T_link @ shape.origin
    c = T[:3, :3].T @ (centre - T[:3, 3])  # sphere centre in the shape's frame
    if shape.kind == "sphere":
        return float(np.linalg.norm(c)) < shape.size[0] + radius
    if shape.kind == "box":
        half = np.asarray(shape.size) / 2
        return float(np.linalg.norm(np.maximum(np.abs(c) - half, 0.0))) < radius
    r, length = shape.size
    dr = max(float(np.linalg.norm(c[:2])) - r, 0.0)
    dz = max(abs(float(c[2])) - length / 2, 0.0)
    return float(np.hypot(dr, dz)) < radius


@pytest.mark.slow
def test_obstacle_pairs_agree_with_closed_form_geometry(hand):
    problem = gt.GraspProblem.from_task("glass3")
    posture = _reference_posture(hand, problem)
    frames = hand.link_frames(posture)
    shapes = link_shapes(hand.urdf, "collision")
    rng = np.random.default_rng(0)
    palm = posture.palm_pose[:3].numpy()
    agree = total = 0
    for trial in range(150):
        centre = palm + rng.uniform(-0.12, 0.12, 3)
        radius = float(rng.uniform(0.005, 0.03))
        data = {**problem.to_mapping(), "obstacles": [{"shape": "sphere", "size": [radius],
                                                        "pose": [*centre.tolist(), 0, 0, 0]}]}
        data.pop("object")
        scene = CollisionScene(hand, gt.GraspProblem.from_mapping(data, source=f"sphere {trial}"))
        got = {link for link, _ in scene.check(posture).obstacle_pairs}
        want = {s.link for s in shapes if _sphere_hits(s, frames[s.link], centre, radius)}
        agree += got == want
        total += 1
    assert agree / total >= 0.99, (agree, total)


def test_count_is_distinct_link_obstacle_pairs(hand):
    problem = gt.GraspProblem.from_task("glass3")
    posture = _reference_posture(hand, problem)
    palm = posture.palm_pose[:3].tolist()
    far = [1.0, 1.0, 1.0, 0, 0, 0]
    data = {**problem.to_mapping(), "obstacles": [
        {"shape": "box", "size": [0.3, 0.3, 0.3], "pose": [*palm, 0, 0, 0]},  # swallows the hand
        {"shape": "sphere", "size": [0.01], "pose": far}]}
    data.pop("object")
    report = CollisionScene(hand, gt.GraspProblem.from_mapping(data, source="box")).check(posture)
    linked = {s.link for s in link_shapes(hand.urdf, "collision")}
    assert report.obstacle_pairs == sorted((link, 0) for link in linked)  # each link once, none with the far sphere
    assert report.count == len(linked)


def test_object_penetration_over_2mm_counts_except_the_touching_fingertips(hand):
    problem = gt.GraspProblem.from_task("glass3")
    posture = _reference_posture(hand, problem)
    scene = CollisionScene(hand, problem)
    assert scene.touching == {"thumb_distal", "index_distal", "middle_distal"}
    report = scene.check(posture)
    assert all(depth > 0.002 for depth in report.object_links.values())
    assert not set(report.object_links) & scene.touching
    assert report.count == len(report.obstacle_pairs) + len(report.object_links)
    loose = CollisionScene(hand, problem, object_tolerance=0.05).check(posture)
    assert loose.object_links == {} and loose.count == 0


def test_a_hand_far_from_everything_has_no_collision(hand):
    problem = gt.GraspProblem.from_task("block5")
    home = hand.home_posture()
    away = Posture(palm_pose=torch.tensor([2.0, 2.0, 2.0, 0, 0, 0], dtype=torch.float64), fingers=home.fingers,
                   body=home.body)
    assert CollisionScene(hand, problem).check(away).count == 0


@pytest.mark.parametrize("kind", ["box", "cylinder", "sphere"])
def test_every_primitive_kind_collides_as_an_obstacle(hand, kind):
    problem = gt.GraspProblem.from_task("glass3")
    posture = _reference_posture(hand, problem)
    palm = posture.palm_pose[:3].tolist()
    size = {"box": [0.02, 0.02, 0.02], "cylinder": [0.01, 0.02], "sphere": [0.01]}[kind]
    data = {**problem.to_mapping(), "obstacles": [{"shape": kind, "size": size, "pose": [*palm, 0, 0, 0]}]}
    report = CollisionScene(hand, gt.GraspProblem.from_mapping(data, source=kind)).check(posture)
    assert ("palm", 0) in report.obstacle_pairs


def test_checking_many_postures_at_once_agrees_with_one_at_a_time():
    """CollisionScene.check_many (one pass of forward kinematics) gives each posture the report
    check gives it alone: an arm among the obstacles of env1, random postures, some colliding."""
    robot = gt.load_robot("arm_hand")
    problem = gt.GraspProblem.from_task("env1")
    scene = CollisionScene(robot, problem)
    g = torch.Generator().manual_seed(3)
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    postures = [Posture(palm_pose=torch.zeros(6, dtype=torch.float64),
                        fingers=flo + (fhi - flo) * torch.rand(flo.shape, generator=g, dtype=torch.float64),
                        body=lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64))
                for _ in range(12)]
    many = scene.check_many(postures)
    alone = [CollisionScene(robot, problem).check(p) for p in postures]
    assert many == alone
    assert any(r.count > 0 for r in many) and any(r.count == 0 for r in many)
