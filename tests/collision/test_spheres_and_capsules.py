"""The proxy's robot models, through their modules' public functions: link spheres in clusters
(collision/spheres.py) and the self-collision capsules and boxes (collision/self_collision.py),
against hand formulas."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.self_collision import SMALL_BOX_M, SelfCollisionModel
from graspnet_torch.collision.spheres import CLUSTER, shape_spheres, sphere_clusters
from graspnet_torch.robot.frames import Attachment, link_attachments
from graspnet_torch.robot.geometry import LinkShape, link_shapes

KW = {"dtype": torch.float64, "device": "cpu"}


@pytest.mark.parametrize("name", ["hand", "manus"])
def test_clusters_hold_every_sphere_in_its_attachment_frame(name):
    """Each link's spheres (shape_spheres, placed by its attachment pose) in order, at most
    CLUSTER per cluster, each inside its cluster's bounding sphere, in its link's frame id."""
    robot = gt.load_robot(name)
    shapes = link_shapes(robot.urdf, "collision")
    attach = link_attachments(robot, [s.link for s in shapes])
    ids = {}

    def frame_id(a: Attachment) -> int:
        return ids.setdefault((a.kind, a.finger, a.level), len(ids))

    cl = sphere_clusters(shapes, attach, frame_id)
    assert cl.links == list(dict.fromkeys(s.link for s in shapes))
    for link in cl.links:
        G = attach[link].pose
        want = np.concatenate([shape_spheres(s)[0] for s in shapes if s.link == link]) @ G[:3, :3].T + G[:3, 3]
        want_r = np.concatenate([shape_spheres(s)[1] for s in shapes if s.link == link])
        rows = [k for k, li in enumerate(cl.link) if cl.links[li] == link]
        assert {cl.frame[k] for k in rows} == {frame_id(attach[link])}
        real = ~np.isnan(cl.radii[rows])  # (k, CLUSTER)
        np.testing.assert_allclose(cl.local[rows][:, :3].transpose(0, 2, 1)[real], want, atol=1e-15)
        np.testing.assert_allclose(cl.radii[rows][real], want_r, atol=0)
        assert all(r.sum() == CLUSTER for r in real[:-1])  # full clusters, the last may be partial
    assert cl.n_spheres == sum(len(shape_spheres(s)[1]) for s in shapes)
    real = ~np.isnan(cl.radii)
    reach = np.linalg.norm(cl.local[:, :3] - cl.bound[:, :3], axis=1) + np.nan_to_num(cl.radii)  # (C, CLUSTER)
    assert bool(np.all(reach[real] <= np.repeat(cl.bound_r[:, None], CLUSTER, 1)[real] + 1e-12))
    assert bool(np.all(cl.local[:, 3][real] == 1.0)) and bool(np.all(cl.local[:, 3][~real] == 0.0))


def _cylinder(link: str, r: float, length: float) -> LinkShape:
    return LinkShape.placed(link, "cylinder", (r, length), np.eye(4))


def _frames(shift: np.ndarray) -> torch.Tensor:
    """(3, T, 3, 4): frame 0 the world, frames 1 and 2 translated by shift (T, 3)."""
    T = len(shift)
    eye = torch.eye(4, dtype=torch.float64)[:3].expand(T, 3, 4)
    moved = eye.clone()
    moved[..., 3] = torch.as_tensor(shift)
    return torch.stack([eye, moved, moved])


def test_capsules_and_boxes_hit_within_their_radii_and_the_clearance():
    """Two parallel cylinders (r = 0.02, axis along z) at distance d hit when d < 2 r + clearance;
    a capsule against a large box (a box for self-collision) when the capsule's axis comes within
    r + clearance of the box's face; two boxes are left unchecked; dropped pairs never hit."""
    r, clearance = 0.02, 0.005
    big = LinkShape.placed("c", "box", (0.4, 0.4, 0.4), np.eye(4))  # half 0.2 > SMALL_BOX_M: a box
    assert 0.2 > SMALL_BOX_M
    small = LinkShape.placed("d", "box", (0.3, 0.3, 0.3), np.eye(4))
    shapes = [_cylinder("a", r, 0.2), _cylinder("b", r, 0.2), big, small]
    attach = {"a": Attachment("body", 0), "b": Attachment("body", 1), "c": Attachment("body", 2),
              "d": Attachment("body", 0)}
    pairs = [("a", "b"), ("a", "c"), ("c", "d")]
    model = SelfCollisionModel(shapes, pairs, attach, lambda a: a.level, clearance, KW)
    assert model.tested and model.unchecked == [("c", "d")]
    d = np.linspace(0.0, 0.5, 101)
    d = d[np.abs(d - (2 * r + clearance)) > 1e-9]
    d = d[np.abs(d - (0.2 + r + clearance)) > 1e-9]
    shift = np.stack([d, np.zeros_like(d), np.zeros_like(d)], 1)
    hits = model.hits(_frames(shift)).numpy()  # (T, 3)
    np.testing.assert_array_equal(hits[:, 0], d < 2 * r + clearance)
    np.testing.assert_array_equal(hits[:, 1], d < 0.2 + r + clearance)  # the capsule's axis vs the face at x = 0.2
    assert not hits[:, 2].any()
    model.drop(torch.tensor([True, False, False]))
    assert model.unchecked == [("c", "d"), ("a", "b")]
    hits = model.hits(_frames(shift)).numpy()
    assert not hits[:, 0].any() and hits[:, 1].any()


@pytest.mark.parametrize("which", ["oddhand", "coupled"])
def test_attachments_place_every_link_where_forward_kinematics_does(tmp_path, which):
    """Each link's attachment (its level frame, then its pose there) gives the link's frame of
    the URDF's forward kinematics at random postures: the odd hand, whose middle finger has no
    base of its own before the ring finger's chain (its links are the ring's, not the middle's),
    and a hand whose fingers share joints (at random values: the finger bases they move given
    per posture, as the solver gives them to the collision proxy)."""
    from graspnet_torch.robot.frames import RobotLevels
    from graspnet_torch.robot.robot import Posture
    from graspnet_torch.robot.transforms import pose_to_rt
    from tests.odd_hands import write_coupled_hand, write_oddhand

    robot = gt.load_robot(write_oddhand(tmp_path) if which == "oddhand" else write_coupled_hand(tmp_path))
    links = list(dict.fromkeys(s.link for s in link_shapes(robot.urdf, "collision")))
    attach = link_attachments(robot, links)
    levels = RobotLevels(robot, torch.float64)
    g = torch.Generator().manual_seed(2)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    top = max(a.level for a in attach.values())
    for _ in range(5):
        pose = torch.rand(6, generator=g, dtype=torch.float64) - 0.5
        q = lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)
        shared = bases = None
        if robot.shared.n:
            u = torch.rand(robot.shared.n, generator=g, dtype=torch.float64).numpy()
            shared = torch.as_tensor(robot.shared.lower + (robot.shared.upper - robot.shared.lower) * u)
            bases = tuple(b[None] for b in robot.base_frames(shared))
        frames = robot.link_frames(Posture(pose, q, torch.zeros(0, dtype=torch.float64), shared))
        R, t = pose_to_rt(pose)
        W = torch.cat([R, t[:, None]], 1)
        finger = levels.finger_levels(W[None], q[None], top, bases)
        for link, a in attach.items():
            F = W if a.kind == "palm" else finger[a.level][0, a.finger]
            F4 = torch.cat([F, torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=torch.float64)])
            np.testing.assert_allclose(F4.numpy() @ a.pose, frames[link], atol=1e-6, rtol=0, err_msg=link)
