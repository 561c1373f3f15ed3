"""A mobile robot's own hazards: the floor it stands on and its arm against its own links
(``floor`` and ``self_collision`` in the robot config), in FCL and in the torch proxy."""

from __future__ import annotations

import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene, environment_obstacles, self_collision_pairs
from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.robot import Posture

POINTS = {"robot": "manus", "points": [[0.9, 0.2, 0.8], [0.9, 0.13, 0.8]]}


@pytest.fixture(scope="module")
def manus():
    return gt.load_robot("manus")


def _posture(robot, q: torch.Tensor) -> Posture:
    home = robot.home_posture()
    return Posture(palm_pose=home.palm_pose, fingers=home.fingers, body=q.double())


def test_self_collision_pairs_skip_adjacent_rigid_and_home_contacts(manus):
    pairs = self_collision_pairs(manus)
    assert ("platform", "gripper") in pairs and ("platform", "elbow_pitch_link") in pairs
    assert ("platform", "arm_mount") not in pairs  # adjacent (a fixed joint)
    assert ("wrist_yaw_link", "wrist_roll_link") not in pairs  # adjacent through a link without geometry
    assert ("jaw_1", "jaw_2") not in pairs  # rigidly joined: they never move apart
    scene = CollisionScene(manus, gt.GraspProblem.from_mapping(POINTS, source="points"))
    assert scene.check(manus.home_posture()).self_pairs == []
    assert self_collision_pairs(gt.load_robot("hand")) == []  # the hand does not ask for them


def test_floor_is_an_obstacle_under_the_platform(manus):
    problem = gt.GraspProblem.from_mapping(POINTS, source="points")
    floor = environment_obstacles(manus, problem)[-1]
    assert len(environment_obstacles(manus, problem)) == len(problem.obstacles) + 1
    assert floor.pose[2] + floor.size[2] / 2 == pytest.approx(-0.001)  # its top: 1 mm below the platform
    scene = CollisionScene(manus, problem)
    assert scene.check(manus.home_posture()).count == 0
    # the gripper driven down to the floor: shoulder pitched down, elbow straight
    q = manus.home_posture().body.clone()
    names = manus.body_joint_names
    q[names.index("shoulder_pitch")] = -1.4
    q[names.index("elbow_pitch")] = 0.0
    report = scene.check(_posture(manus, q))
    assert any(obstacle == 0 for _link, obstacle in report.obstacle_pairs), report  # index 0: the floor here


def test_proxy_self_collision_agrees_with_fcl(manus):
    """On random configurations (about half of them fold the arm into itself), the proxy's
    self-collision verdict agrees with FCL's and misses few of FCL's collisions."""
    problem = gt.GraspProblem.from_mapping(POINTS, source="points")
    proxy = CollisionProxy(manus, problem, dtype=torch.float64)
    scene = CollisionScene(manus, problem)
    lo, hi = (torch.as_tensor(a) for a in manus.body_limits)
    q = lo + (hi - lo) * torch.rand(150, 9, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    levels, palm = proxy.body_levels_and_palm(q)
    hits = proxy.self_hits(palm, torch.zeros(150, 0, 0, dtype=torch.float64), q, levels).any(-1)
    fcl = torch.tensor([bool(scene.check(_posture(manus, q[k])).self_pairs) for k in range(150)])
    assert 0.2 < float(fcl.float().mean()) < 0.8  # both kinds are present
    assert float((hits == fcl).float().mean()) >= 0.93
    assert float((fcl & ~hits).float().mean()) <= 0.03


def test_clearance_only_adds_obstacle_collisions(manus):
    problem = gt.GraspProblem.from_task("cube")
    plain = CollisionProxy(manus, problem, dtype=torch.float64)
    wide = CollisionProxy(manus, problem, dtype=torch.float64, clearance=0.02)
    lo, hi = (torch.as_tensor(a) for a in manus.body_limits)
    q = lo + (hi - lo) * torch.rand(200, 9, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    none = torch.zeros(200, 0, 0, dtype=torch.float64)
    la, pa = plain.body_levels_and_palm(q)
    c_plain = plain.pairs(pa, none, q, la)  # (T, links, table + cube + floor)
    c_wide = wide.pairs(pa, none, q, la)
    assert bool((c_wide | ~c_plain).all()) and bool((c_wide & ~c_plain).any())
    assert bool((c_wide[..., -1] == c_plain[..., -1]).all())  # the floor has no margin


@pytest.mark.parametrize("key, value, message", [
    ("floor", "low", "floor"),
    ("floor", [0.0, 1.0], "floor"),
    ("self_collision", "yes", "self_collision"),
])
def test_bad_floor_and_self_collision_are_refused(key, value, message):
    raw = yaml.safe_load((repo_root() / "configs" / "robot" / "manus.yaml").read_text())
    raw[key] = value
    with pytest.raises(ConfigError, match=message):
        RobotCfg.from_mapping(raw, "manus.yaml")


def test_links_riding_the_planar_base_are_not_tested_against_the_floor(manus):
    """The platform and the arm's mount move only with the base (x, y, yaw): the proxy skips them
    against the floor (their clusters never reach the narrow phase), and FCL agrees that they
    never touch it anywhere in the base's range."""
    problem = gt.GraspProblem.from_mapping(POINTS, source="points")
    proxy = CollisionProxy(manus, problem, dtype=torch.float64)
    attach = {link: ("body", 3) for link in ("platform", "arm_mount")} | {"gripper": ("body", 9)}
    assert proxy._riding_base(manus, attach) == {"platform", "arm_mount"}
    floor = len(problem.obstacles)  # the floor follows the problem's obstacles
    for g in proxy._groups:
        if floor in g["index"]:
            col = g["index"].index(floor)
            riding = [k for k, li in enumerate(proxy._cluster_link.tolist()) if proxy.links[li] == "platform"]
            assert not bool(g["bound_pos"][riding, 0, col].any())
    scene = CollisionScene(manus, problem)
    lo, hi = (torch.as_tensor(a[:3]) for a in manus.body_limits)
    g = torch.Generator().manual_seed(9)
    for _ in range(10):
        q = manus.home_posture().body.clone()
        q[:3] = lo + (hi - lo) * torch.rand(3, generator=g, dtype=torch.float64)
        assert not any(link in ("platform", "arm_mount") for link, _o in scene.check(_posture(manus, q)).obstacle_pairs)
