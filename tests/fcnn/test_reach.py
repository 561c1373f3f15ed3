"""Reaching motions (eq. 6-8) and iterative improvement (eq. 5)."""

from __future__ import annotations

import torch

from graspnet_torch.fcnn.reach import ReachCfg, min_singular_value, reach_motion, reach_steps
from tests.fcnn.conftest import limits


def test_step_count_is_eq_6():
    r_st = 0.005
    d = torch.tensor([0.0, 0.004, 0.0049, 0.0051, 0.0123, 0.05 - 1e-9, 0.1 + 1e-9], dtype=torch.float64)
    T = reach_steps(d, r_st)
    assert T.tolist() == [1, 1, 1, 2, 3, 10, 21]
    ratio = d / r_st
    assert bool(((T - 1 < ratio + 1e-12) & (ratio < T)).all())  # T - 1 <= d/r_st < T


def _pair(index_kernel, index_chain, gen, n):
    lo, hi = limits(index_chain, torch.float64)
    mid = (lo + hi) / 2
    q_goal = mid + 0.3 * (hi - lo) * (torch.rand(n, 4, generator=gen, dtype=torch.float64) - 0.5)
    q0 = mid + 0.3 * (hi - lo) * (torch.rand(n, 4, generator=gen, dtype=torch.float64) - 0.5)
    return q0, index_kernel.position(q_goal), lo, hi


def test_motion_follows_the_straight_line(index_kernel, index_chain, gen):
    """The fingertip visits X_D(k) of eq. 7: on the segment X_C -> X_D, k/T of the way."""
    q0, targets, lo, hi = _pair(index_kernel, index_chain, gen, 64)
    cfg = ReachCfg(r_st=0.005, r_e=1e-5)
    res = reach_motion(index_kernel.position_jacobian, q0, targets, lo, hi, cfg)
    ok = res.success & (res.steps > 3)
    assert int(ok.sum()) >= 10
    start = index_kernel.position(q0)
    for b in torch.nonzero(ok).squeeze(1).tolist():
        T = int(res.steps[b])
        assert T == int(res.start_error[b] // cfg.r_st) + 1
        tips = index_kernel.position(res.path[b, : T - 1])
        k = torch.arange(1, T, dtype=torch.float64).unsqueeze(1)
        waypoints = (1 - k / T) * start[b] + (k / T) * targets[b]
        # eq. 8 is a first-order step: each point lands within a small fraction of r_st of X_D(k)
        assert (tips - waypoints).norm(dim=-1).max() < 0.2 * cfg.r_st
        assert float(res.error[b]) < cfg.r_e
        step = (tips[1:] - tips[:-1]).norm(dim=-1)
        assert bool((step < 1.3 * cfg.r_st).all())


def test_close_start_is_improvement_only(index_kernel, index_chain, gen):
    q0, _, lo, hi = _pair(index_kernel, index_chain, gen, 32)
    targets = index_kernel.position(q0) + 0.002 * torch.nn.functional.normalize(
        torch.randn(32, 3, generator=gen, dtype=torch.float64), dim=-1)
    res = reach_motion(index_kernel.position_jacobian, q0, targets, lo, hi, ReachCfg(r_st=0.005, r_e=1e-5))
    assert bool((res.steps == 1).all())
    idx, post = res.stored_points()
    assert idx.tolist() == torch.nonzero(res.success).squeeze(1).tolist()  # one improved point each
    assert (index_kernel.position(post) - targets[idx]).norm(dim=-1).max() < 1e-5


def test_leaving_joint_limits_rejects(index_kernel, index_chain):
    lo, hi = limits(index_chain, torch.float64)
    q0 = torch.tensor([[0.0, 0.3, 0.5, 0.3]], dtype=torch.float64)
    beyond = q0.clone()
    beyond[0, 1] = hi[1] + 0.4  # MCP beyond its upper limit, everything else inside
    target = index_kernel.position(beyond)
    res = reach_motion(index_kernel.position_jacobian, q0, target, lo, hi, ReachCfg())
    assert not bool(res.success[0])
    assert res.stored_points()[1].shape[0] == 0


def test_singular_start_rejects(index_kernel, index_chain):
    lo, hi = limits(index_chain, torch.float64)
    straight = torch.zeros(1, 4, dtype=torch.float64)  # fully extended finger: J loses rank
    _, J = index_kernel.position_jacobian(straight)
    assert float(min_singular_value(J)) < 1e-9
    target = index_kernel.position(torch.tensor([[0.0, 0.5, 0.5, 0.2]], dtype=torch.float64))
    assert not bool(reach_motion(index_kernel.position_jacobian, straight, target, lo, hi).success[0])
