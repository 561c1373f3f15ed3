"""Damped pseudo-inverse steps (eq. 5) against the formulas they implement; refine (the LM) on chains."""

from __future__ import annotations

import torch

from graspnet_torch.least_squares import damped_pinv_step, solve3_symmetric
from graspnet_torch.robot import ChainKernel
from graspnet_torch.robot.ik import refine
from tests.conftest import uniform


def test_solve3_matches_linalg(gen):
    M = torch.randn(50, 3, 3, generator=gen, dtype=torch.float64)
    A = M @ M.transpose(-1, -2) + 0.1 * torch.eye(3, dtype=torch.float64)
    b = torch.randn(50, 3, generator=gen, dtype=torch.float64)
    assert (solve3_symmetric(A, b) - torch.linalg.solve(A, b)).abs().max() < 1e-10


def test_undamped_step_is_the_pseudo_inverse(gen):
    J = torch.randn(20, 3, 4, generator=gen, dtype=torch.float64)
    e = torch.randn(20, 3, generator=gen, dtype=torch.float64)
    expected = (torch.linalg.pinv(J) @ e.unsqueeze(-1)).squeeze(-1)
    assert (damped_pinv_step(J, e) - expected).abs().max() < 1e-10


def test_damped_step_formula(gen):
    J = torch.randn(20, 3, 4, generator=gen, dtype=torch.float64)
    e = torch.randn(20, 3, generator=gen, dtype=torch.float64)
    lam = 0.05
    A = J @ J.transpose(-1, -2) + lam**2 * torch.eye(3, dtype=torch.float64)
    expected = (J.transpose(-1, -2) @ torch.linalg.solve(A, e).unsqueeze(-1)).squeeze(-1)
    assert (damped_pinv_step(J, e, lam) - expected).abs().max() < 1e-10


def test_refine_reduces_error_and_respects_limits(hand, gen):
    spec = hand.fingers["index"].chain.spec
    kernel = ChainKernel(spec)
    lo, hi = torch.tensor(spec.lower), torch.tensor(spec.upper)
    q_true = uniform(spec.lower, spec.upper, 200, gen)
    targets = kernel.position(q_true)
    q0 = torch.clamp(q_true + 0.15 * torch.randn(q_true.shape, generator=gen, dtype=torch.float64), lo, hi)
    e0 = torch.linalg.norm(kernel.position(q0) - targets, dim=-1)
    q, e = refine(kernel.position_jacobian, q0, targets, lo, hi, iterations=5)
    assert (q >= lo).all() and (q <= hi).all()
    assert torch.median(e) < 0.01 * torch.median(e0)
    assert torch.allclose(e, torch.linalg.norm(kernel.position(q) - targets, dim=-1))


def test_refine_on_every_finger_at_once_never_worsens_a_finger(hand, gen):
    """robot/ik.refine is the LM of least_squares: a (F, n) batch through the robot's fingertips
    (one call for all fingers), each finger's distance never above its start's, within limits."""
    lo, hi = (torch.as_tensor(a) for a in hand.finger_limits)  # (F, n)
    for _ in range(5):
        q0 = lo + (hi - lo) * torch.rand(lo.shape, generator=gen, dtype=torch.float64)
        tips, _ = hand.fingertips_base_jacobian(q0)
        targets = tips + 0.02 * torch.randn(tips.shape, generator=gen, dtype=torch.float64)
        e0 = torch.linalg.norm(tips - targets, dim=-1)
        q, e = refine(hand.fingertips_base_jacobian, q0, targets, lo, hi, 40)
        assert q.shape == q0.shape and e.shape == e0.shape
        assert (q >= lo).all() and (q <= hi).all() and (e <= e0).all()
        assert torch.allclose(e, torch.linalg.norm(hand.fingertips_base_jacobian(q)[0] - targets, dim=-1))


def test_step_for_chains_with_fewer_than_three_joints(gen):
    J = torch.randn(20, 3, 2, generator=gen, dtype=torch.float64)
    e = torch.randn(20, 3, generator=gen, dtype=torch.float64)
    expected = (torch.linalg.pinv(J) @ e.unsqueeze(-1)).squeeze(-1)
    assert (damped_pinv_step(J, e) - expected).abs().max() < 1e-10


def test_one_step_for_any_system_with_one_damping_per_row(gen):
    """The package's one damped step (LM, gripper settling, FCNN refinement): k x n systems of any
    size, a lambda per row, both forms (n >= k: J^T (J J^T + l^2 I)^-1 e; n < k: (J^T J + l^2 I)^-1 J^T e)."""
    for k, n in ((6, 9), (15, 26), (6, 3)):
        J = torch.randn(20, k, n, generator=gen, dtype=torch.float64)
        e = torch.randn(20, k, generator=gen, dtype=torch.float64)
        lam = torch.rand(20, generator=gen, dtype=torch.float64)
        A = J @ J.transpose(-1, -2) + (lam**2).view(-1, 1, 1) * torch.eye(k, dtype=torch.float64)
        expected = (J.transpose(-1, -2) @ torch.linalg.solve(A, e).unsqueeze(-1)).squeeze(-1)
        assert (damped_pinv_step(J, e, lam) - expected).abs().max() < 1e-9
