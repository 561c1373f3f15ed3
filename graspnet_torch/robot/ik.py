"""Position-only inverse kinematics steps with the damped pseudo-inverse (paper eq. 5 and 8).

    theta(k+1) = theta(k) + J^+(theta(k)) (X_D - g(theta(k))),
    J^+ = J^T (J J^T + lambda^2 I)^-1        (damped least squares; lambda = 0 is eq. 5 exactly)

The 3x3 system is solved in closed form (adjugate), which is exact and several times faster than
``torch.linalg.solve`` on small batches.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

__all__ = ["damped_pinv_step", "limited_step", "refine", "solve3_symmetric"]


def solve3_symmetric(A: Tensor, b: Tensor) -> Tensor:
    """Solve ``A x = b`` for symmetric 3x3 ``A`` by the adjugate formula.

    A: (..., 3, 3); b: (..., 3) -> x: (..., 3). Singular systems give inf/nan, as division would.
    """
    a0, a1, a2 = A.unbind(-2)
    c0 = torch.linalg.cross(a1, a2)
    c1 = torch.linalg.cross(a2, a0)
    c2 = torch.linalg.cross(a0, a1)
    adj = torch.stack([c0, c1, c2], dim=-2)  # adj(A) = adj(A)^T for symmetric A
    det = (a0 * c0).sum(-1, keepdim=True)
    return (adj @ b.unsqueeze(-1)).squeeze(-1) / det


def damped_pinv_step(J: Tensor, err: Tensor, damping: float = 0.0) -> Tensor:
    """Joint step ``J^T (J J^T + damping^2 I)^-1 err``.

    J: (..., 3, n); err: (..., 3) -> (..., n). Chains with fewer than 3 joints use the equivalent
    ``(J^T J + damping^2 I)^-1 J^T err`` (their J J^T is singular).
    """
    n = J.shape[-1]
    if n < 3:
        A = J.transpose(-1, -2) @ J
        if damping:
            A = A + (damping * damping) * torch.eye(n, dtype=J.dtype, device=J.device)
        return torch.linalg.solve(A, (J.transpose(-1, -2) @ err.unsqueeze(-1))).squeeze(-1)
    A = J @ J.transpose(-1, -2)
    if damping:
        A = A + (damping * damping) * torch.eye(3, dtype=J.dtype, device=J.device)
    y = solve3_symmetric(A, err)
    return (J.transpose(-1, -2) @ y.unsqueeze(-1)).squeeze(-1)


def limited_step(J: Tensor, err: Tensor, q: Tensor, lower: Tensor, upper: Tensor, damping: float) -> Tensor:
    """A damped pseudo-inverse step that respects joint limits by re-solving, not just clamping.

    Joints whose step would cross a limit are locked (their Jacobian columns zeroed) and the step
    is solved again with the others; a redundant chain can usually still make the full Cartesian
    correction that way, where a plain clamp would stall against the limit. Returns the new
    posture, within limits.

    J: (..., 3, n); err: (..., 3); q: (..., n); lower, upper: broadcastable to q -> (..., n).
    """
    dq = damped_pinv_step(J, err, damping)
    q_new = q + dq
    over = (q_new < lower) | (q_new > upper)
    if bool(over.any()):
        locked = damped_pinv_step(J * (~over).unsqueeze(-2).to(J.dtype), err, damping)
        q_new = torch.where(over.any(-1, keepdim=True), q + locked, q_new)
    return torch.clamp(q_new, lower, upper)


def refine(
    fk_jacobian: Callable[[Tensor], tuple[Tensor, Tensor]],
    q: Tensor,
    targets: Tensor,
    lower: Tensor,
    upper: Tensor,
    iterations: int,
    damping: float = 1e-3,
) -> tuple[Tensor, Tensor]:
    """Iterative improvement of eq. 5 within the joint limits (see :func:`limited_step`).

    Args:
        fk_jacobian: q (..., n) -> (p (..., 3), J (..., 3, n)), e.g. ``ChainKernel.position_jacobian``.
        q: (..., n) start postures; targets: (..., 3); lower, upper: (n,) or broadcastable limits.
        iterations: number of steps.
        damping: lambda of the damped pseudo-inverse (metres); keeps steps bounded near singularities.
    Returns:
        q: (..., n) refined postures within limits; error: (..., ) distance to the targets (m).
    """
    p, J = fk_jacobian(q)
    for _ in range(iterations):
        q = limited_step(J, targets - p, q, lower, upper, damping)
        p, J = fk_jacobian(q)
    return q, torch.linalg.vector_norm(targets - p, dim=-1)
