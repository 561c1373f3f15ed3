"""A mobile robot's own hazards: the floor it stands on and its arm against its own links
(``floor`` and ``self_collision`` in the robot config), in FCL and in the torch proxy."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene, environment_obstacles, self_collision_pairs
from graspnet_torch.collision.proxy import CollisionProxy
from graspnet_torch.collision.self_collision import segment_distance_sq, segment_meets_box, self_collision_primitive
from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.frames import Attachment, riding_base_links
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
    attach = {link: Attachment("body", 3) for link in ("platform", "arm_mount")} | {"gripper": Attachment("body", 9)}
    assert riding_base_links(manus, attach) == {"platform", "arm_mount"}
    floor = len(problem.obstacles)  # the floor follows the problem's obstacles
    for g, tests in zip(proxy.groups, proxy.thresholds, strict=True):
        if floor in g.index:
            col = g.index.index(floor)
            riding = [k for k, li in enumerate(proxy.clusters.link) if proxy.links[li] == "platform"]
            assert not bool(tests.bound_pos[riding, 0, col].any())
    scene = CollisionScene(manus, problem)
    lo, hi = (torch.as_tensor(a[:3]) for a in manus.body_limits)
    g = torch.Generator().manual_seed(9)
    for _ in range(10):
        q = manus.home_posture().body.clone()
        q[:3] = lo + (hi - lo) * torch.rand(3, generator=g, dtype=torch.float64)
        assert not any(link in ("platform", "arm_mount") for link, _o in scene.check(_posture(manus, q)).obstacle_pairs)


def test_segment_distance_matches_a_dense_search():
    """The closed-form segment-segment distance (Ericson) against the minimum over a 301 x 301
    grid of both segments' points, float64, with points (zero-length segments) and parallel pairs
    among them: never above the grid's minimum, and below it by no more than the grid's spacing."""
    g = torch.Generator().manual_seed(5)
    p1, q1, p2, q2 = (torch.rand(60, 3, generator=g, dtype=torch.float64) for _ in range(4))
    q1[:10] = p1[:10]  # the first is a point
    q2[10:20] = p2[10:20]  # the second is a point
    q2[20:25], p2[20:25] = p2[25:30], p2[25:30]  # both points
    q2[30:40] = p2[30:40] + (q1[30:40] - p1[30:40]) * 0.7  # parallel
    got = segment_distance_sq(p1, q1, p2, q2).sqrt()
    s = torch.linspace(0, 1, 301, dtype=torch.float64)
    a = p1[:, None] + s[None, :, None] * (q1 - p1)[:, None]  # (N, 301, 3)
    b = p2[:, None] + s[None, :, None] * (q2 - p2)[:, None]
    grid = torch.cdist(a, b).flatten(1).amin(1)
    step = ((q1 - p1).norm(dim=1) + (q2 - p2).norm(dim=1)) / 300
    assert bool((got <= grid + 1e-12).all())
    assert bool((grid - got <= step).all()), (grid - got).max()


def test_segment_meets_box_matches_sampling():
    """The slab test against points sampled along each segment (2001 of them): a segment whose
    samples enter the box shrunk by 1e-3 meets it; one whose samples miss the box grown by 1e-3
    does not."""
    g = torch.Generator().manual_seed(6)
    p0, p1 = (torch.rand(400, 3, generator=g, dtype=torch.float64) * 2 - 1 for _ in range(2))
    p1[:40] = p0[:40]  # points
    p1[40:80, 1] = p0[40:80, 1]  # parallel to a slab
    half = torch.tensor([0.3, 0.2, 0.4], dtype=torch.float64)
    got = segment_meets_box(p0, p1, half)
    t = torch.linspace(0, 1, 2001, dtype=torch.float64)
    x = (p0[:, None] + t[None, :, None] * (p1 - p0)[:, None]).abs()  # (N, 2001, 3)
    inner = (x <= half - 1e-3).all(-1).any(-1)
    outer = (x <= half + 1e-3).all(-1).any(-1)
    assert bool((got | ~inner).all()) and bool((~got | outer).all())
    assert 0.2 < float(got.double().mean()) < 0.8  # both verdicts present


@pytest.mark.slow
def test_the_floor_half_space_agrees_with_the_spheres_heights(manus):
    """The proxy tests the floor as a half-space: link l hits it where one of its spheres (placed
    by pytorch-kinematics' link frames, float64) dips below the floor's top by its radius."""
    from graspnet_torch.collision.scene import FLOOR_GAP
    from graspnet_torch.robot.geometry import link_shapes

    problem = gt.GraspProblem.from_mapping(POINTS, source="points")
    proxy = CollisionProxy(manus, problem, dtype=torch.float64)
    lo, hi = (torch.as_tensor(a) for a in manus.body_limits)
    q = lo + (hi - lo) * torch.rand(200, 9, generator=torch.Generator().manual_seed(8), dtype=torch.float64)
    levels, palm = proxy.body_levels_and_palm(q)
    got = proxy.pairs(palm, torch.zeros(200, 0, 0, dtype=torch.float64), q, levels)[..., len(problem.obstacles)]
    want = torch.zeros_like(got)
    for k in range(200):
        frames = manus.link_frames(_posture(manus, q[k]))
        for shape in link_shapes(manus.urdf, "collision"):
            if shape.link in ("platform", "arm_mount"):  # they ride the base (the test above)
                continue
            centres, radii = shape_spheres(shape)
            z = (frames[shape.link][:3, :3] @ centres.T)[2] + frames[shape.link][2, 3]
            if bool(np.any(z - radii < -FLOOR_GAP)):
                want[k, proxy.links.index(shape.link)] = True
    assert bool((got == want).all())
    assert 0.05 < float(want.any(-1).double().mean()) < 0.95  # both verdicts present


def test_self_collision_primitives_of_the_manus_links(manus):
    """Cylinders become capsules along their axis (ends r/4 inside the flat faces), the wrist's
    sphere a capsule of length 0, the thin jaws capsules along their longest side (radius the
    half-diagonal of the cross-section), the platform stays a box."""
    from graspnet_torch.robot.geometry import link_shapes

    shapes = {s.link: s for s in link_shapes(manus.urdf, "collision")}
    kind, ends, r = self_collision_primitive(shapes["elbow_pitch_link"])
    radius, length = shapes["elbow_pitch_link"].size
    axis = shapes["elbow_pitch_link"].origin[:3, 2]
    assert kind == "capsule" and r == radius
    assert np.allclose(ends[1] - ends[0], (length - radius / 2) * axis)
    kind, ends, r = self_collision_primitive(shapes["wrist_yaw_link"])
    assert kind == "capsule" and np.allclose(ends[0], ends[1]) and r == shapes["wrist_yaw_link"].size[0]
    kind, ends, r = self_collision_primitive(shapes["jaw_1"])
    assert kind == "capsule" and np.isclose(np.linalg.norm(ends[1] - ends[0]), 0.08)
    assert np.isclose(r, np.hypot(0.006, 0.015))
    kind, pose, half = self_collision_primitive(shapes["platform"])
    assert kind == "box" and np.allclose(half, np.array(shapes["platform"].size) / 2)
    assert np.allclose(pose, shapes["platform"].origin)


def test_self_collisions_agree_with_every_pair_tested_directly():
    """The scene tests a self-collision pair only where its links' shapes' boxes meet; on 150
    random MANUS configurations it finds exactly the pairs that FCL finds when every pair's
    shapes are tested directly (placed from the URDF's link frames)."""
    import fcl
    import numpy as np
    import torch

    import graspnet_torch as gt
    from graspnet_torch.collision import CollisionScene, self_collision_pairs
    from graspnet_torch.collision.geometry import fcl_geometry
    from graspnet_torch.robot.geometry import link_shapes
    from graspnet_torch.robot.robot import Posture
    from graspnet_torch.robot.transforms import rt_to_pose

    robot = gt.load_robot("manus")
    scene = CollisionScene(robot, gt.GraspProblem.from_task("cube"))
    shapes = link_shapes(robot.urdf, "collision")
    pairs = self_collision_pairs(robot)
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    g = torch.Generator().manual_seed(3)
    found = 0
    for _ in range(150):
        body = lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)
        posture = Posture(rt_to_pose(*robot.palm_frame(body)), torch.zeros(0, 0, dtype=torch.float64), body)
        frames = robot.link_frames(posture)

        def objects(link, frames=frames):
            out = []
            for s in shapes:
                if s.link == link:
                    T = frames[link] @ s.origin
                    geometry = fcl.BVHModel() if s.kind == "mesh" else fcl_geometry(s.kind, s.size)
                    if s.kind == "mesh":
                        geometry.beginModel(len(s.mesh.vertices), len(s.mesh.faces))
                        geometry.addSubModel(np.asarray(s.mesh.vertices), np.asarray(s.mesh.faces))
                        geometry.endModel()
                    out.append(fcl.CollisionObject(geometry, fcl.Transform(T[:3, :3], T[:3, 3])))
            return out

        direct = sorted((a, b) for a, b in pairs
                        if any(fcl.collide(x, y, fcl.CollisionRequest(), fcl.CollisionResult())
                               for x in objects(a) for y in objects(b)))
        assert sorted(scene.check(posture).self_pairs) == direct
        found += bool(direct)
    assert found > 10  # the configurations do collide with themselves, often
