"""The one Levenberg-Marquardt's residual models beyond fingertips: a frame and a back-off target."""

from __future__ import annotations

import math

import torch

import graspnet_torch as gt
from graspnet_torch.least_squares import LMOptions, frame_model, levenberg_marquardt


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
    out = levenberg_marquardt(frame_model(robot.palm_frame_jacobian, R0), goal, q0, lo, hi, 100, LMOptions(tol=1e-6))
    R, t = robot.palm_frame(out.x)
    assert ((t - goal[:, :3]).norm(dim=-1) < 1e-4).all()
    cos = ((R0 @ R.transpose(-1, -2)).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    angle = torch.arccos(cos.clamp(-1, 1))
    assert (angle < math.radians(0.5)).all()
    assert (out.x >= lo).all() and (out.x <= hi).all()


def test_converged_replaces_the_norm_test_row_by_row():
    """A model with a residual that must vanish and one that need only be small: with
    ``converged`` both rows stop once the first is within 1e-9 and the second under 0.1, where
    ``tol`` on the whole norm (never reached: the second stays 0.05) runs them to the budget."""

    def f(x, rows):  # residuals x0 and 0.3 + x1 (the second cannot reach 0 inside x1 >= 0)
        return torch.stack([x[:, 0], 0.3 + x[:, 1]], 1), torch.eye(2, dtype=x.dtype).expand(x.shape[0], 2, 2)

    lo, hi = torch.tensor([-10.0, -0.25], dtype=torch.float64), torch.tensor([10.0, 10.0], dtype=torch.float64)
    x0 = torch.tensor([[1.0, 0.0], [5.0, 3.0]], dtype=torch.float64)
    goal = torch.zeros(2, dtype=torch.float64)
    plain = levenberg_marquardt(f, goal, x0, lo, hi, 50, LMOptions(tol=1e-9))
    assert (plain.steps == 50).all()  # |e| >= 0.05 at the bound: never below tol

    def near(e):
        return (e[:, 0].abs() < 1e-9) & (e[:, 1].abs() < 0.1)

    out = levenberg_marquardt(f, goal, x0, lo, hi, 50, LMOptions(tol=1e-9, converged=near))
    assert out.steps[0] < 50 and out.steps[1] < 50
    assert near(goal - out.value).all()
