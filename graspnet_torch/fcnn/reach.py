"""Reaching motions and iterative improvement (paper section 3.2, eq. 4-8), batched over targets.

From a start posture theta(0) with fingertip X_C = g(theta(0)) towards X_D:

    e(0) = |X_D - g(theta(0))|                                                    (4)
    T - 1 < |X_D - X_C| / r_st < T,  i.e.  T = floor(|X_D - X_C| / r_st) + 1       (6)
    X_D(k) = (1 - k/T) X_C + (k/T) X_D  for k < T,   X_D(k) = X_D  for k >= T      (7)
    theta(k+1) = theta(k) + J^+(theta(k)) (X_D(k+1) - g(theta(k)))                 (8)

For k >= T the update is eq. 5 (iterative improvement), run until e(k) < r_e. When e(0) < r_st,
eq. 6 gives T = 1 and the motion is eq. 5 alone: the paper's two cases are one procedure, and only
what is stored differs (a single improved point, or the T points of the motion).

A motion is rejected when a step leaves the joint limits or reaches a singular posture (the
smallest relevant singular value of J below ``singular_tol``), or when it has not converged to r_e
within ``max_improve`` extra steps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.least_squares import damped_pinv_step
from graspnet_torch.settings import setting

__all__ = ["ReachCfg", "ReachResult", "min_singular_value", "reach_motion", "reach_steps"]


@dataclass(frozen=True)
class ReachCfg:
    """Thresholds of the reaching motion.

    Attributes:
        r_st: Cartesian step of the straight-line motion (m); below it, improvement only.
        r_e: convergence threshold of the iterative improvement (m).
        max_improve: improvement steps allowed after the T motion steps.
        singular_tol: a posture whose smallest singular value of J (m/rad) falls below this is
            singular.
        limit_tol: slack on the joint limits (rad) before a step counts as leaving them.
        damping: lambda of the damped pseudo-inverse (m); tiny, for numerical safety only.
    """

    r_st: float = setting(0.005, lo=0.0, lo_open=True, hi=1.0)
    r_e: float = setting(1e-4, lo=0.0, lo_open=True, hi=1.0)
    max_improve: int = setting(10, lo=0, hi=10_000)
    singular_tol: float = setting(0.001, lo=0.0, hi=1.0)
    limit_tol: float = setting(1e-6, lo=0.0, hi=1.0)
    damping: float = setting(1e-5, lo=0.0, hi=1.0)


@dataclass
class ReachResult:
    """Outcome of a batch of reaching motions.

    Attributes:
        q: (B, n) final postures.
        error: (B,) final distance to the target (m).
        success: (B,) motion accepted (no limit, no singularity, converged to r_e).
        steps: (B,) T of eq. 6.
        path: (B, K, n) postures theta(1), ..., theta(K); for each target the first ``steps``
            entries hold theta(1)..theta(T-1) and the final (improved) posture in place of
            theta(T).
        start_error: (B,) e(0).
    """

    q: Tensor
    error: Tensor
    success: Tensor
    steps: Tensor
    path: Tensor
    start_error: Tensor

    def stored_points(self) -> tuple[Tensor, Tensor]:
        """The postures a successful motion adds to a training set: its T points (a single
        improved posture when T = 1). Returns (target index (P,), posture (P, n))."""
        B, K, _n = self.path.shape
        k = torch.arange(K, device=self.path.device)
        keep = (k.unsqueeze(0) < self.steps.unsqueeze(1)) & self.success.unsqueeze(1)
        owner = torch.arange(B, device=self.path.device).unsqueeze(1).expand(B, K)
        return owner[keep], self.path[keep]


def reach_steps(distance: Tensor, r_st: float) -> Tensor:
    """T of eq. 6 for each distance: the integer with T - 1 < d / r_st < T (d / r_st integral
    gives d / r_st + 1)."""
    return torch.floor(distance / r_st).long() + 1


def min_singular_value(J: Tensor) -> Tensor:
    """Smallest of the min(3, n) leading singular values of J (..., 3, n)."""
    n = J.shape[-1]
    r = min(3, n)
    eig = torch.linalg.eigvalsh(J @ J.transpose(-1, -2))  # ascending, 3 values, 3 - r of them ~0
    return torch.sqrt(torch.clamp(eig[..., 3 - r], min=0.0))


def reach_motion(
    fk_jacobian: Callable[[Tensor], tuple[Tensor, Tensor]],
    q0: Tensor,
    targets: Tensor,
    lower: Tensor,
    upper: Tensor,
    cfg: ReachCfg = ReachCfg(),
) -> ReachResult:
    """Batched reaching motions (eq. 6-8) followed by iterative improvement (eq. 5).

    Args:
        fk_jacobian: q (B, n) -> (p (B, 3), J (B, 3, n)), e.g. ``ChainKernel.position_jacobian``.
        q0: (B, n) start postures (within limits); targets: (B, 3) X_D.
        lower, upper: (n,) joint limits.
    """
    B, n = q0.shape
    p, J = fk_jacobian(q0)
    start = p
    start_error = torch.linalg.vector_norm(targets - p, dim=-1)
    T = reach_steps(start_error, cfg.r_st)
    K = int(T.max()) if B else 0
    path = q0.new_zeros(B, max(K, 1), n)
    q = q0.clone()
    alive = (q0 >= lower - cfg.limit_tol).all(-1) & (q0 <= upper + cfg.limit_tol).all(-1)
    alive &= min_singular_value(J) >= cfg.singular_tol
    T_f = T.to(q0.dtype)
    for k in range(K + cfg.max_improve):
        frac = torch.clamp((k + 1) / T_f, max=1.0).unsqueeze(-1)
        waypoint = (1 - frac) * start + frac * targets
        err = torch.linalg.vector_norm(targets - p, dim=-1)
        moving = alive & ((k < T) | (err >= cfg.r_e))  # motion steps, then improve until r_e
        if not bool(moving.any()):
            break
        step = damped_pinv_step(J, waypoint - p, cfg.damping)
        q_new = torch.where(moving.unsqueeze(-1), q + step, q)
        inside = (q_new >= lower - cfg.limit_tol).all(-1) & (q_new <= upper + cfg.limit_tol).all(-1)
        p_new, J_new = fk_jacobian(q_new)
        regular = min_singular_value(J_new) >= cfg.singular_tol
        alive = alive & (~moving | (inside & regular))
        q, p, J = q_new, p_new, J_new
        if k < K:
            path[:, k] = q
    error = torch.linalg.vector_norm(targets - p, dim=-1)
    success = alive & (error < cfg.r_e)
    # the final, improved posture stands in for theta(T)
    idx = (T - 1).clamp(min=0, max=max(K - 1, 0))
    path[torch.arange(B), idx] = q
    return ReachResult(q=q, error=error, success=success, steps=T, path=path, start_error=start_error)
