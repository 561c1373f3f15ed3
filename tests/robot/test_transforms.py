"""Pose convention: R = Rz(rz) Ry(ry) Rx(rx) (URDF rpy, fixed axes); round trips."""

from __future__ import annotations

import math

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from graspnet_torch.robot import transforms as tf
from graspnet_torch.robot.transforms import rpy_to_matrix_np


def _elementary(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


angles = st.floats(-math.pi, math.pi, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(angles, angles, angles)
def test_rpy_is_fixed_axis_zyx_product(rx, ry, rz):
    expected = _elementary(2, rz) @ _elementary(1, ry) @ _elementary(0, rx)
    got = tf.rpy_to_matrix(torch.tensor([rx, ry, rz], dtype=torch.float64)).numpy()
    np.testing.assert_allclose(got, expected, atol=1e-14)
    np.testing.assert_allclose(rpy_to_matrix_np((rx, ry, rz)), expected, atol=1e-14)


@settings(max_examples=60, deadline=None)
@given(angles, st.floats(-1.5, 1.5), angles)
def test_matrix_to_rpy_round_trip(rx, ry, rz):
    rpy = torch.tensor([rx, ry, rz], dtype=torch.float64)
    back = tf.matrix_to_rpy(tf.rpy_to_matrix(rpy))
    np.testing.assert_allclose(tf.rpy_to_matrix(back).numpy(), tf.rpy_to_matrix(rpy).numpy(), atol=1e-12)
    np.testing.assert_allclose(back.numpy(), rpy.numpy(), atol=1e-9)


def test_gimbal_lock_gives_same_rotation():
    for ry in (math.pi / 2, -math.pi / 2):
        rpy = torch.tensor([0.3, ry, -0.7], dtype=torch.float64)
        R = tf.rpy_to_matrix(rpy)
        np.testing.assert_allclose(tf.rpy_to_matrix(tf.matrix_to_rpy(R)).numpy(), R.numpy(), atol=1e-12)


def test_pose_matrix_round_trip_batched(gen):
    pose = torch.rand(7, 3, 6, generator=gen, dtype=torch.float64) * 2 - 1
    T = tf.pose_to_matrix(pose)
    assert T.shape == (7, 3, 4, 4)
    np.testing.assert_allclose(tf.matrix_to_pose(T).numpy(), pose.numpy(), atol=1e-12)
    np.testing.assert_allclose(T[..., 3, :].numpy(), np.broadcast_to([0, 0, 0, 1], (7, 3, 4)))


def test_numpy_twins_match_torch(gen):
    pose = torch.rand(6, generator=gen, dtype=torch.float64) * 6 - 3
    T = tf.pose_to_matrix_np(pose.numpy())
    np.testing.assert_allclose(T, tf.pose_to_matrix(pose).numpy(), atol=1e-15)
    np.testing.assert_allclose(tf.pose_to_matrix_np(pose.tolist()), T, atol=0)
    np.testing.assert_allclose(tf.matrix_to_pose_np(T), tf.matrix_to_pose(tf.pose_to_matrix(pose)).numpy(), atol=1e-15)


def test_points_round_trip_and_inverse(gen):
    pose = torch.rand(5, 6, generator=gen, dtype=torch.float64)
    pts = torch.rand(5, 3, generator=gen, dtype=torch.float64)
    R, t = tf.pose_to_rt(pose)
    np.testing.assert_allclose(tf.untransform_points(R, t, tf.transform_points(R, t, pts)).numpy(), pts.numpy(),
                               atol=1e-14)
    Ri, ti = tf.invert(R, t)
    np.testing.assert_allclose(tf.transform_points(Ri, ti, pts).numpy(), tf.untransform_points(R, t, pts).numpy(),
                               atol=1e-14)
    Rc, tc = tf.compose(R, t, Ri, ti)
    np.testing.assert_allclose(Rc.numpy(), np.broadcast_to(np.eye(3), (5, 3, 3)), atol=1e-14)
    np.testing.assert_allclose(tc.numpy(), 0, atol=1e-14)


def test_degrees_conversion():
    pose = torch.tensor([0.1, -0.2, 0.3, 90.0, -45.0, 180.0], dtype=torch.float64)
    rad = tf.pose_from_degrees(pose)
    np.testing.assert_allclose(rad.numpy(), [0.1, -0.2, 0.3, math.pi / 2, -math.pi / 4, math.pi])
    np.testing.assert_allclose(tf.pose_to_degrees(rad).numpy(), pose.numpy())


def test_place_points_np_is_each_frame_applied_to_each_point():
    rng = np.random.default_rng(0)
    T = np.stack([tf.pose_to_matrix_np(np.concatenate([rng.normal(size=3), rng.uniform(-3, 3, 3)])) for _ in range(5)])
    points = rng.normal(size=(7, 3))
    placed = tf.place_points_np(T, points)
    assert placed.shape == (5, 7, 3)
    for n in range(5):
        for s in range(7):
            assert np.allclose(placed[n, s], T[n, :3, :3] @ points[s] + T[n, :3, 3], atol=1e-14)
