"""The one Levenberg-Marquardt's residual models beyond fingertips: a frame and a back-off target."""

from __future__ import annotations

import math

import torch

import graspnet_torch as gt
from graspnet_torch.least_squares import frame_model, levenberg_marquardt


def test_a_back_off_target_is_a_frame_residual_on_the_lm():
    """The palm moved 5 cm away from a point, its orientation kept (motion/reach's back-off), as
    a frame model on the LM: reached within 0.1 mm and 0.5 degree from several postures at once."""
    robot = gt.load_robot("arm_hand")
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    gen = torch.Generator().manual_seed(0)
    q0 = lo + (hi - lo) * (0.3 + 0.4 * torch.rand(6, lo.shape[0], generator=gen, dtype=torch.float64))
    R0, t0 = robot.palm_frame(q0)
    away = t0 - torch.tensor([0.3, 0.0, 0.2], dtype=torch.float64)  # away from a point (a grasp's contacts)
    goal = torch.cat([t0 + 0.05 * away / away.norm(dim=-1, keepdim=True), torch.zeros(6, 3, dtype=torch.float64)], 1)
    out = levenberg_marquardt(frame_model(robot.palm_frame_jacobian, R0), goal, q0, lo, hi, 100, tol=1e-6)
    R, t = robot.palm_frame(out.x)
    assert ((t - goal[:, :3]).norm(dim=-1) < 1e-4).all()
    cos = ((R0 @ R.transpose(-1, -2)).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    angle = torch.arccos(cos.clamp(-1, 1))
    assert (angle < math.radians(0.5)).all()
    assert (out.x >= lo).all() and (out.x <= hi).all()
