"""Points against primitive obstacles (collision/primitives.py): the groups' signed distances
against trimesh's on the same shapes (an independent recomputation), the hit test against the
signed distance, batches of problems, and the floor as a half-space."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from graspnet_torch.collision.primitives import PrimitiveGroup, group_thresholds, primitive_groups
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.tasks.problem import Shape

KW = {"dtype": torch.float64, "device": "cpu"}


def _mesh(shape: Shape) -> trimesh.Trimesh:
    """The shape as a trimesh mesh in the world (a cylinder with 1024 sections: within 5e-6 r)."""
    if shape.kind == "box":
        mesh = trimesh.creation.box(extents=shape.size)
    elif shape.kind == "cylinder":
        mesh = trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[1], sections=1024)
    else:
        mesh = trimesh.creation.icosphere(subdivisions=6, radius=shape.size[0])
    return mesh.apply_transform(pose_to_matrix_np(shape.pose))


SHAPES = [
    Shape("box", (0.2, 0.1, 0.3), np.array([0.1, -0.2, 0.3, 0.3, -0.5, 1.2])),
    Shape("cylinder", (0.05, 0.25), np.array([-0.1, 0.1, 0.2, 1.0, 0.2, -0.4])),
    Shape("sphere", (0.08,), np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])),
    Shape("box", (0.05, 0.4, 0.02), np.array([0.2, 0.2, -0.1, 0.0, 0.0, 0.7])),
]


def _points(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-0.4, 0.6, size=(n, 3))


def test_groups_stack_the_elements_by_kind():
    groups = primitive_groups([SHAPES], KW)
    assert [g.kind for g in groups] == ["box", "cylinder", "sphere"]
    box = groups[0]
    assert isinstance(box, PrimitiveGroup) and box.index == [0, 3] and box.columns.tolist() == [0, 3]
    assert box.R.shape == (1, 2, 3, 3) and box.t.shape == (1, 2, 3) and box.size.shape == (1, 2, 3)
    np.testing.assert_allclose(box.size[0, 1].numpy(), [0.025, 0.2, 0.01])
    np.testing.assert_allclose(groups[1].size[0, 0].numpy(), [0.05, 0.125])
    assert box.centre is None and box.radius is None


def test_signed_distances_match_trimesh():
    """sd of points in every element's frame (PrimitiveGroup.local) equals trimesh's signed distance
    (which is positive inside) to the same shape placed in the world."""
    groups = primitive_groups([SHAPES], KW)
    for g in groups:
        for col, k in enumerate(g.index):
            x = SHAPES[k].pose[:3] + np.random.default_rng(k).uniform(-0.2, 0.2, size=(400, 3))  # about it
            got = g.signed_distance(g.local(torch.as_tensor(x).view(1, -1, 3))[0]).numpy()  # (N, O)
            want = -trimesh.proximity.signed_distance(_mesh(SHAPES[k]), x)
            tol = 1e-4 * SHAPES[k].size[0] if SHAPES[k].kind != "box" else 1e-12
            np.testing.assert_allclose(got[:, col], want, atol=tol, err_msg=SHAPES[k].kind)
            assert (got[:, col] < 0).any() and (got[:, col] > 0).any()  # points inside and outside


@pytest.mark.parametrize("thr", [0.01, 0.05])
def test_hits_are_the_signed_distance_below_the_threshold(thr):
    groups = primitive_groups([SHAPES], KW)
    x = torch.as_tensor(_points(2000, seed=1)).view(1, -1, 3)
    for g in groups:
        p = g.local(x)[0]
        O = len(g.index)
        thr_sq = torch.full((O,), thr ** 2, dtype=torch.float64)
        got = g.hits(p, torch.ones(O, dtype=torch.bool), thr_sq)
        sd = g.signed_distance(p)
        want = sd < thr
        near = (sd - thr).abs() < 1e-12  # ties within rounding: either verdict
        assert bool(((got == want) | near).all())
        assert bool(want.any()) and bool((~want).any())
        assert not bool(g.hits(p, torch.zeros(O, dtype=torch.bool), thr_sq).any())  # thr <= 0: never

def test_a_batch_of_problems_takes_each_trials_problem():
    """Two problems with the same kinds in the same order: trial t's points are compared with
    problem pid[t]'s elements, as a group of that problem alone would."""
    moved = [Shape(s.kind, tuple(v * 1.5 for v in s.size), s.pose + np.array([0.05, -0.02, 0.1, 0.2, 0.0, -0.3]))
             for s in SHAPES]
    batch = primitive_groups([SHAPES, moved], KW)
    alone = [primitive_groups([SHAPES], KW), primitive_groups([moved], KW)]
    T = 6
    x = torch.as_tensor(_points(T * 5, seed=2)).view(T, 5, 3)
    pid = torch.tensor([0, 1, 1, 0, 1, 0])
    for k, g in enumerate(batch):
        got = g.signed_distance(g.local(x, pid), g.size[pid].unsqueeze(1))  # (T, 5, O)
        for t in range(T):
            a = alone[int(pid[t])][k]
            want = a.signed_distance(a.local(x[t:t + 1]))[0]
            torch.testing.assert_close(got[t], want, atol=1e-15, rtol=0)


def test_the_floor_is_a_half_space_at_the_slabs_top():
    floor = Shape("box", (4.0, 4.0, 0.1), np.array([0.0, 0.0, -0.051, 0.0, 0.0, 0.0]))
    groups = primitive_groups([[SHAPES[2], floor]], KW, floor=1)
    plane = groups[-1]
    assert plane.kind == "plane" and plane.index == [1] and plane.top == pytest.approx(-0.001)
    x = torch.tensor([[[0.3, -2.0, 0.01], [5.0, 5.0, -0.002]]], dtype=torch.float64)
    sd = plane.signed_distance(plane.local(x))[0, :, 0]
    torch.testing.assert_close(sd, torch.tensor([0.011, -0.001], dtype=torch.float64))


def test_thresholds_follow_radii_margins_and_exemptions():
    """thr = rho - margin per sphere and element; padding (NaN radii), exempt clusters and
    thresholds <= 0 are never tested; the bounding spheres' reach is bound_r - margin."""
    g = primitive_groups([SHAPES], KW)[0]  # the boxes: elements 0 and 3
    radii = np.array([[0.01, 0.02, np.nan], [0.03, np.nan, np.nan]])
    margin = [-0.005, 0.0, 0.0, 0.015]
    exempt = np.zeros((2, 4), dtype=bool)
    exempt[1, 0] = True
    th = group_thresholds(g, radii, np.array([0.05, 0.01]), margin, exempt, KW)
    assert th.pos.tolist() == [[[True, False], [True, True], [False, False]],
                               [[False, True], [False, False], [False, False]]]
    np.testing.assert_allclose(th.thr_sq[0, :, 0].numpy(), [0.015 ** 2, 0.025 ** 2, 0.0])
    np.testing.assert_allclose(th.thr_sq[1, 0].numpy(), [0.0, 0.015 ** 2])  # exempt from element 0
    np.testing.assert_allclose(th.bound_thr_sq[:, 0].numpy(), [[0.055 ** 2, 0.035 ** 2], [0.015 ** 2, 0.0]])
    assert th.bound_pos[:, 0].tolist() == [[True, True], [False, False]] and th.bound_r is None
