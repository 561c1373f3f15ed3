"""The loop's torch collision proxy against FCL (the engine of record), and its pieces against
independent references: sphere centres against pytorch-kinematics link frames, batched ==
looped."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision import CollisionScene
from graspnet_torch.collision.proxy import FINGER_GAP_M, CollisionProxy
from graspnet_torch.collision.scene import finger_pairs
from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture
from graspnet_torch.robot.transforms import pose_to_rt, rt_to_pose
from graspnet_torch.solver.search_space import palm_search_space, sample_hand_configurations


@pytest.fixture(scope="module")
def arm_hand():
    return gt.load_robot("arm_hand")


def _random_arm(robot, problem, n, seed):
    """Arm configurations uniform in the problem's bounds, finger joints uniform in their limits."""
    from graspnet_torch.solver.arm import arm_bounds

    g = torch.Generator().manual_seed(seed)
    lo, hi = (torch.as_tensor(a) for a in arm_bounds(robot, problem))
    body = lo + (hi - lo) * torch.rand(n, lo.numel(), generator=g, dtype=torch.float64)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = flo + (fhi - flo) * torch.rand(n, *flo.shape, generator=g, dtype=torch.float64)
    return body, q


def _agreement(robot, problem, body, q, palm):
    proxy = CollisionProxy(robot, problem, dtype=torch.float64)
    scene = CollisionScene(robot, problem)
    counts = proxy.count(palm, q, body)
    pose = rt_to_pose(*palm)
    fcl = torch.tensor([scene.count(Posture(palm_pose=pose[k], fingers=q[k],
                                            body=body[k] if body is not None else torch.zeros(0)))
                        for k in range(len(q))])
    verdict = ((counts > 0) == (fcl > 0)).double().mean().item()
    exact = (counts == fcl).double().mean().item()
    return verdict, exact, (fcl > 0).double().mean().item()


@pytest.mark.parametrize("task", ["env1", "fig10"])
@pytest.mark.slow
def test_proxy_agrees_with_fcl_on_random_arm_configurations(arm_hand, task):
    """>= 99 % of random configurations get the same verdict (collision-free or not) from the
    proxy as from FCL, on a set where a good part collides; the counts themselves on >= 90 %
    (the sphere model rounds box edges and cylinder rims: README, "Collisions")."""
    problem = gt.GraspProblem.from_task(task)
    body, q = _random_arm(arm_hand, problem, 600, seed=0)
    verdict, exact, colliding = _agreement(arm_hand, problem, body, q, arm_hand.palm_frame(body))
    print(f"{task}: verdict {verdict:.4f}, count {exact:.4f}, colliding {colliding:.3f}")
    assert 0.2 < colliding < 0.95
    assert verdict >= 0.99, verdict
    assert exact >= 0.90, exact


@pytest.mark.slow
def test_proxy_agrees_with_fcl_for_the_free_hand_and_its_object():
    hand = gt.load_robot("hand")
    problem = gt.GraspProblem.from_task("glass3")
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), 600, torch.Generator().manual_seed(1))
    verdict, exact, colliding = _agreement(hand, problem, None, q, pose_to_rt(pose))
    print(f"glass3: verdict {verdict:.4f}, count {exact:.4f}, colliding {colliding:.3f}")
    assert 0.1 < colliding < 0.9
    assert verdict >= 0.99, verdict
    assert exact >= 0.90, exact


def test_sphere_centres_follow_the_link_frames(arm_hand):
    """Every sphere centre equals its link frame (``Robot.link_frames_of``, float64) times its offset."""
    problem = gt.GraspProblem.from_task("env1")
    proxy = CollisionProxy(arm_hand, problem, dtype=torch.float64)
    body, q = _random_arm(arm_hand, problem, 3, seed=2)
    centres = proxy.sphere_centres(arm_hand.palm_frame(body), q, body)  # (T, C, K, 3)
    R, t = arm_hand.palm_frame(body)
    for k in range(3):
        frames = arm_hand.link_frames(Posture(palm_pose=rt_to_pose(R[k], t[k]), fingers=q[k], body=body[k]))
        expected = []
        for link in proxy.links:
            for c in proxy.link_spheres[link]:  # sphere centres in the link frame
                expected.append(c @ frames[link][:3, :3].T + frames[link][:3, 3])
        expected = np.concatenate(expected)
        valid = torch.as_tensor(~np.isnan(proxy.clusters.radii))  # (C, K): real spheres, in link order
        got = centres[k][valid].numpy()
        assert got.shape == expected.shape
        assert np.allclose(got, expected, atol=1e-10)


@pytest.mark.parametrize("kind", ["sphere", "cylinder", "box"])
def test_spheres_approximate_their_primitive(arm_hand, kind):
    """Points sampled inside the primitive are inside the union of its spheres except near its
    edges (box: within 0.4 rho of an edge or 0.2 rho of a face between two spheres; cylinder:
    within 0.03 r of the mantle between two
    spheres) and outside points are outside it except at a cylinder's ends (overshoot <= 3r/4 on
    the axis) and near a box's edges."""
    shape = next(s for s in link_shapes(arm_hand.urdf, "collision") if s.kind == kind and s.link != "torso")
    centres, radii = shape_spheres(shape)
    inv = np.linalg.inv(shape.origin)
    local = centres @ inv[:3, :3].T + inv[:3, 3]
    rng = np.random.default_rng(0)
    if kind == "sphere":
        assert np.allclose(local, 0) and radii[0] == shape.size[0]
        return
    if kind == "box":
        half = np.asarray(shape.size) / 2
        assert np.all(np.abs(local) + radii[:, None] <= half + 1e-12)  # never beyond a face
        inside = rng.uniform(-half, half, (4000, 3))
        depth = np.sort(half - np.abs(inside), axis=1)
        skip = (depth[:, :2] < 0.4 * half.min()).all(axis=1) | (depth[:, 0] < 0.2 * half.min())
    else:
        r, length = shape.size
        assert np.all(np.linalg.norm(local[:, :2], axis=1) + radii <= r + 1e-12)  # never beyond the mantle
        assert np.all(np.abs(local[:, 2]) + radii <= length / 2 + 0.75 * r + 1e-12)
        u = rng.uniform(-1, 1, (8000, 3))
        inside = u[np.linalg.norm(u[:, :2], axis=1) < 1] * [r, r, length / 2]
        skip = r - np.linalg.norm(inside[:, :2], axis=1) < 0.03 * r
    covered = (np.linalg.norm(inside[:, None] - local[None], axis=-1) < radii).any(axis=1)
    assert covered[~skip].all()


def test_batched_counts_equal_one_at_a_time(arm_hand):
    problem = gt.GraspProblem.from_task("env2")
    proxy = CollisionProxy(arm_hand, problem, dtype=torch.float64)
    body, q = _random_arm(arm_hand, problem, 40, seed=3)
    R, t = arm_hand.palm_frame(body)
    batched = proxy.count((R, t), q, body)
    looped = torch.cat([proxy.count((R[k:k + 1], t[k:k + 1]), q[k:k + 1], body[k:k + 1]) for k in range(40)])
    assert torch.equal(batched, looped) and int(batched.max()) > 0


def test_touching_fingertips_do_not_count_but_other_links_in_the_object_do(arm_hand):
    """At the reference posture nothing collides; pushing the whole arm into the glass makes the
    palm and finger links count, and the contact fingers' distal links never do."""
    from graspnet_torch.solver.api import reference_posture

    problem = gt.GraspProblem.from_task("env1")
    ref = reference_posture(arm_hand, problem)
    proxy = CollisionProxy(arm_hand, problem, dtype=torch.float64)
    R, t = arm_hand.palm_frame(ref.body.unsqueeze(0))
    assert int(proxy.count((R, t), ref.fingers.unsqueeze(0), ref.body.unsqueeze(0))) == 0
    glass = torch.as_tensor(problem.object.pose[:3])
    pairs = proxy.pairs((R, glass.view(1, 3) + 0 * t), ref.fingers.unsqueeze(0), ref.body.unsqueeze(0))
    obj = pairs[0, :, -1]
    inside = {proxy.links[i] for i in obj.nonzero().flatten().tolist()}
    assert "palm" in inside
    assert not inside & {"thumb_distal", "index_distal", "middle_distal"}


def test_the_proxy_arm_chain_gives_the_kernel_palm_frame(arm_hand):
    """The environment takes the palm from the proxy's arm chain when it counts collisions: the
    same frame as the robot's kinematics kernel (float64)."""
    problem = gt.GraspProblem.from_task("env1")
    proxy = CollisionProxy(arm_hand, problem, dtype=torch.float64)
    body, _ = _random_arm(arm_hand, problem, 5, seed=4)
    levels, (R, t) = proxy.body_levels_and_palm(body)
    R0, t0 = arm_hand.palm_frame(body)
    assert len(levels) == 7
    assert torch.allclose(R, R0, atol=1e-12) and torch.allclose(t, t0, atol=1e-12)


@pytest.mark.parametrize("as_mesh", [False, True])
def test_link_depths_agree_with_fcl_on_the_free_hand_and_its_object(as_mesh, tmp_path):
    """The surface model's depth residual per link (CollisionProxy.link_depths, the spheres' signed
    distances; a mesh object's by its convex pieces) against FCL's penetration of the same link
    (no tolerance, no link exempt), on random hand configurations around glass3 (its cylinder, or
    the cylinder as a mesh file): a link FCL finds 3 mm or more inside has a positive depth, and a
    link the proxy finds 3 mm or more inside is inside by FCL too."""
    from graspnet_torch.tasks.objects import as_mesh as mesh_of

    hand = gt.load_robot("hand")
    problem = gt.GraspProblem.from_task("glass3")
    if as_mesh:
        problem = mesh_of(problem, tmp_path)
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), 300, torch.Generator().manual_seed(3))
    proxy = CollisionProxy(hand, problem, dtype=torch.float64, touching=False)
    palm = pose_to_rt(pose)
    depths = proxy.link_depths(proxy.penetrations(proxy.sphere_centres(palm, q).flatten(1, 2)))  # (T, L)
    scene = CollisionScene(hand, problem, object_tolerance=0.0, touching=False)
    fcl = np.zeros(tuple(depths.shape))
    for k in range(len(q)):
        inside = scene.check(Posture(palm_pose=pose[k], fingers=q[k], body=torch.zeros(0))).object_links
        for link, depth in inside.items():
            if link in proxy.links:
                fcl[k, proxy.links.index(link)] = depth
    proxy_depth = depths.numpy()
    deep_by_fcl, deep_by_proxy = fcl >= 0.003, proxy_depth >= 0.003
    assert deep_by_fcl.sum() > 20 and deep_by_proxy.sum() > 20  # the sample has links well inside
    assert (proxy_depth[deep_by_fcl] > 0).mean() >= 0.99
    assert (fcl[deep_by_proxy] > 0).mean() >= 0.99
    assert (proxy_depth[fcl == 0] == 0).mean() >= 0.95  # and clear links have no depth


def test_overlapping_finger_pairs_agree_with_fcl_fingers_through_each_other():
    """The surface model's fingers-apart residual (CollisionProxy.overlapping_pairs, sphere pairs of
    two fingers within FINGER_GAP_M) against FCL's rule (CollisionScene fingers_apart: two
    fingers' links intersecting), on random hand postures: none at the home posture, and where
    FCL finds two fingers through each other the proxy finds an overlapping pair of those links."""
    hand = gt.load_robot("hand")
    problem = gt.GraspProblem.from_task("glass3")
    proxy = CollisionProxy(hand, problem, dtype=torch.float64, touching=False, fingers_apart=True)
    home = hand.home_posture(torch.float64)
    palm = pose_to_rt(home.palm_pose.unsqueeze(0))
    t, _, _ = proxy.overlapping_pairs(proxy.sphere_centres(palm, home.fingers.unsqueeze(0)).flatten(1, 2))
    assert t.numel() == 0
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), 300, torch.Generator().manual_seed(4))
    t, a, b = proxy.overlapping_pairs(proxy.sphere_centres(pose_to_rt(pose), q).flatten(1, 2))
    link = proxy.sphere_links()
    found = {(int(k), frozenset((proxy.links[int(link[i])], proxy.links[int(link[j])])))
             for k, i, j in zip(t, a, b, strict=True)}
    scene = CollisionScene(hand, problem, object_tolerance=0.001, touching=False, fingers_apart=True)
    through, seen = 0, 0
    for k in range(len(q)):
        report = scene.check(Posture(palm_pose=pose[k], fingers=q[k], body=torch.zeros(0)))
        for x, y in report.self_pairs:
            through += 1
            seen += (k, frozenset((x, y))) in found
    assert through > 20  # random postures put fingers through each other
    assert seen / through >= 0.9, (seen, through)


def test_overlapping_finger_pairs_are_every_overlapping_sphere_pair():
    """The links-first test (bounding spheres, then the spheres of the pairs that meet) finds
    exactly the sphere pairs a test of every pair of two apart links' spheres finds."""
    hand = gt.load_robot("hand")
    problem = gt.GraspProblem.from_task("glass3")
    proxy = CollisionProxy(hand, problem, dtype=torch.float64, touching=False, fingers_apart=True)
    pose, q = sample_hand_configurations(hand, palm_search_space(hand, problem), 200, torch.Generator().manual_seed(5))
    centres = proxy.sphere_centres(pose_to_rt(pose), q).flatten(1, 2)
    t, a, b = proxy.overlapping_pairs(centres)
    link, r = proxy.sphere_links(), proxy.sphere_radii()
    apart = {frozenset((proxy.links.index(x), proxy.links.index(y))) for x, y in finger_pairs(hand)}
    pair = torch.tensor([[frozenset((int(x), int(y))) in apart for y in link] for x in link])
    pair &= (r[:, None] > 0) & (r[None, :] > 0)
    gap = (centres[:, :, None] - centres[:, None, :]).norm(dim=-1)  # (T, S, S): every pair
    k, i, j = ((gap < r[:, None] + r[None, :] + FINGER_GAP_M) & pair.triu(1)).nonzero(as_tuple=True)
    want = set(zip(k.tolist(), i.tolist(), j.tolist(), strict=True))
    got = {(int(k), min(int(i), int(j)), max(int(i), int(j))) for k, i, j in zip(t, a, b, strict=True)}
    assert len(want) > 50 and got == want
