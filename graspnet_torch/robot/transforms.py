"""Rigid transforms in the project's pose convention.

A pose is ``(x, y, z, rx, ry, rz)``: a translation in metres and fixed-axis roll/pitch/yaw in
radians with ``R = Rz(rz) @ Ry(ry) @ Rx(rx)`` (the URDF ``rpy`` convention). Files a person reads
give the angles in degrees; :func:`pose_from_degrees` / :func:`pose_to_degrees` convert.

The torch functions broadcast over leading batch dimensions. The ``*_np`` functions are their
float64 numpy twins for one pose (files, problems, URDF origins, FCL objects), the only numpy
implementation of these conversions in the package.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "compose",
    "frame_point_jacobian",
    "invert",
    "matrix_to_pose",
    "matrix_to_pose_np",
    "matrix_to_rpy",
    "place_points_np",
    "pose_from_degrees",
    "pose_jacobian",
    "pose_to_degrees",
    "pose_to_matrix",
    "pose_to_matrix_np",
    "pose_to_rt",
    "rpy_to_matrix",
    "rpy_to_matrix_np",
    "rt_to_pose",
    "transform_points",
    "untransform_points",
]


def rpy_to_matrix(rpy: Tensor) -> Tensor:
    """Rotation matrices of fixed-axis roll/pitch/yaw angles.

    Args:
        rpy: (..., 3) angles (rx, ry, rz) in radians.
    Returns:
        (..., 3, 3) ``Rz(rz) @ Ry(ry) @ Rx(rx)``.
    """
    c = torch.cos(rpy)
    s = torch.sin(rpy)
    cr, cp, cy = c.unbind(-1)
    sr, sp, sy = s.unbind(-1)
    spsr, spcr = sp * sr, sp * cr
    entries = [cy * cp, cy * spsr - sy * cr, cy * spcr + sy * sr,
               sy * cp, sy * spsr + cy * cr, sy * spcr - cy * sr,
               -sp, cp * sr, cp * cr]
    return torch.stack(entries, dim=-1).unflatten(-1, (3, 3))


def matrix_to_rpy(R: Tensor) -> Tensor:
    """Inverse of :func:`rpy_to_matrix`, with pitch in [-pi/2, pi/2].

    At gimbal lock (``|pitch| = pi/2``) roll is set to 0 and the rotation about z goes to yaw.

    Args:
        R: (..., 3, 3) rotation matrices.
    Returns:
        (..., 3) angles (rx, ry, rz) in radians.
    """
    r00, r10, r20 = R[..., 0, 0], R[..., 1, 0], R[..., 2, 0]
    cp = torch.sqrt(r00 * r00 + r10 * r10)
    pitch = torch.atan2(-r20, cp)
    locked = cp < 1e-9 if R.dtype == torch.float64 else cp < 1e-5
    roll = torch.where(locked, torch.zeros_like(cp), torch.atan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = torch.where(locked, torch.atan2(-R[..., 0, 1], R[..., 1, 1]), torch.atan2(r10, r00))
    return torch.stack([roll, pitch, yaw], dim=-1)


def pose_to_rt(pose: Tensor) -> tuple[Tensor, Tensor]:
    """Split poses into rotation and translation.

    Args:
        pose: (..., 6) ``(x, y, z, rx, ry, rz)``, metres and radians.
    Returns:
        R: (..., 3, 3); t: (..., 3).
    """
    return rpy_to_matrix(pose[..., 3:]), pose[..., :3]


def pose_jacobian(pose: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """A pose's frame and its Jacobian with respect to the pose's six values.

    With ``R = Rz(rz) Ry(ry) Rx(rx)``, ``dR = [w]_x R`` where the angular velocity of each angle is
    the axis it turns about, carried into the world by the rotations applied after it:
    ``w_rx = Rz Ry e_x``, ``w_ry = Rz e_y``, ``w_rz = e_z``; the translation moves with x, y, z.

    Args:
        pose: (..., 6).
    Returns:
        R: (..., 3, 3); t: (..., 3); J: (..., 6, 6), rows d t (3) then w (3), one column per value
        (the frame Jacobian of :func:`frame_point_jacobian`).
    """
    R, t = pose_to_rt(pose)
    yaw = pose[..., 5:]
    lead, kw = pose.shape[:-1], {"dtype": pose.dtype, "device": pose.device}
    w_ry = torch.cat([-torch.sin(yaw), torch.cos(yaw), torch.zeros_like(yaw)], -1).unsqueeze(-1)  # Rz e_y
    w_rz = torch.tensor([[0.0], [0.0], [1.0]], **kw).expand(*lead, 3, 1)
    w = torch.cat([R[..., :, :1], w_ry, w_rz], -1)  # w_rx = Rz Ry e_x = R e_x (Rx leaves e_x)
    top = torch.eye(3, 6, **kw).expand(*lead, 3, 6)
    return R, t, torch.cat([top, torch.cat([torch.zeros_like(w), w], -1)], -2)


def frame_point_jacobian(R: Tensor, J: Tensor, points: Tensor) -> Tensor:
    """Jacobian of points fixed in a moving frame, expressed in its parent: ``p = R y + t``.

    A frame Jacobian J (rows d t / d c (3) and the angular velocity w (3) with ``dR/dc = [w]_x R``)
    gives ``d p / d c = d t / d c + w x (R y)``.

    Args:
        R: (..., 3, 3) the frame; J: (..., 6, n) its Jacobian; points: (..., P, 3) y, in the frame.
    Returns:
        (..., P, 3, n).
    """
    arm = (R.unsqueeze(-3) @ points.unsqueeze(-1)).squeeze(-1).unsqueeze(-1)  # (..., P, 3, 1): R y
    w = J[..., 3:, :].unsqueeze(-3)  # (..., 1, 3, n)
    a0, a1, a2 = arm.unbind(-2)
    w0, w1, w2 = w.unbind(-2)
    turn = torch.stack([w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0], -2)  # w x (R y): (..., P, 3, n)
    return J[..., :3, :].unsqueeze(-3) + turn


def rt_to_pose(R: Tensor, t: Tensor) -> Tensor:
    """Inverse of :func:`pose_to_rt`: (..., 3, 3), (..., 3) -> (..., 6)."""
    return torch.cat([t, matrix_to_rpy(R)], dim=-1)


def pose_to_matrix(pose: Tensor) -> Tensor:
    """(..., 6) poses -> (..., 4, 4) homogeneous matrices."""
    R, t = pose_to_rt(pose)
    T = torch.zeros(*pose.shape[:-1], 4, 4, dtype=pose.dtype, device=pose.device)
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def matrix_to_pose(T: Tensor) -> Tensor:
    """(..., 4, 4) homogeneous matrices -> (..., 6) poses."""
    return rt_to_pose(T[..., :3, :3], T[..., :3, 3])


def transform_points(R: Tensor, t: Tensor, points: Tensor) -> Tensor:
    """Express points given in a frame in its parent: ``R @ p + t``.

    Args:
        R: (..., 3, 3); t: (..., 3); points: (..., 3), all broadcastable.
    Returns:
        (..., 3).
    """
    return (R @ points.unsqueeze(-1)).squeeze(-1) + t


def untransform_points(R: Tensor, t: Tensor, points: Tensor) -> Tensor:
    """Express points given in the parent in the frame ``(R, t)``: ``R^T @ (p - t)``."""
    return ((points - t).unsqueeze(-2) @ R).squeeze(-2)


def compose(R1: Tensor, t1: Tensor, R2: Tensor, t2: Tensor) -> tuple[Tensor, Tensor]:
    """``(R1, t1) o (R2, t2)``: the pose of frame 2 given in frame 1, expressed in frame 1's parent."""
    return R1 @ R2, transform_points(R1, t1, t2)


def invert(R: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
    """Inverse transform: ``(R^T, -R^T t)``."""
    Rt = R.transpose(-1, -2)
    return Rt, -(Rt @ t.unsqueeze(-1)).squeeze(-1)


_DEG = math.pi / 180.0


def pose_from_degrees(pose_deg: Tensor) -> Tensor:
    """(..., 6) pose with angles in degrees -> angles in radians (translation untouched)."""
    scale = torch.tensor([1.0, 1.0, 1.0, _DEG, _DEG, _DEG], dtype=pose_deg.dtype, device=pose_deg.device)
    return pose_deg * scale


def pose_to_degrees(pose: Tensor) -> Tensor:
    """(..., 6) pose with angles in radians -> angles in degrees (translation untouched)."""
    scale = torch.tensor([1.0, 1.0, 1.0, 1 / _DEG, 1 / _DEG, 1 / _DEG], dtype=pose.dtype, device=pose.device)
    return pose * scale


def rpy_to_matrix_np(rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    """float64 numpy :func:`rpy_to_matrix` of one set of angles.

    Args:
        rpy: (3,) angles (rx, ry, rz) in radians (e.g. a URDF ``<origin rpy>``).
    Returns:
        (3, 3) ``Rz(rz) @ Ry(ry) @ Rx(rx)``.
    """
    r, p, y = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def pose_to_matrix_np(pose: Sequence[float] | np.ndarray) -> np.ndarray:
    """float64 numpy :func:`pose_to_matrix` of one pose: (6,) ``(x, y, z, rx, ry, rz)`` -> (4, 4)."""
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix_np(pose[3:6])
    T[:3, 3] = pose[:3]
    return T


def matrix_to_pose_np(T: np.ndarray) -> np.ndarray:
    """float64 numpy :func:`matrix_to_pose` of one matrix: (4, 4) -> (6,) (m, rad)."""
    return matrix_to_pose(torch.as_tensor(T, dtype=torch.float64)).numpy()


def place_points_np(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (s, 3) placed by each of N frames T (N, 4, 4): (N, s, 3), ``R p + t`` (one product
    per frame over all the points: many times faster than a per-point product for large s)."""
    return (T[:, :3, :3] @ np.asarray(points, dtype=np.float64).T).transpose(0, 2, 1) + T[:, None, :3, 3]
