"""Damped least squares: the package's one step (paper eq. 5 and 8), and position-only IK with it.

    theta(k+1) = theta(k) + J^+(theta(k)) (X_D - g(theta(k))),
    J^+ = J^T (J J^T + lambda^2 I)^-1        (damped least squares; lambda = 0 is eq. 5 exactly)

The 3x3 system is solved by LAPACK for a handful of systems and in closed form (adjugate) for
large batches, whichever is faster.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

__all__ = ["damped_pinv_step", "limited_step", "refine", "solve3_symmetric"]

SMALL_BATCH = 256


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


def damped_pinv_step(J: Tensor, err: Tensor, damping: float | Tensor = 0.0) -> Tensor:
    """Step ``J^T (J J^T + damping^2 I)^-1 err``: the one damped-least-squares step of the package
    (the FCNN's refinement, the Levenberg-Marquardt polish, a gripper's settling steps).

    J: (..., k, n); err: (..., k); damping: a number or a tensor broadcastable to the batch (...)
    (one lambda per system) -> (..., n). Systems with fewer unknowns than equations (n < k) use the
    equivalent ``(J^T J + damping^2 I)^-1 J^T err`` (their J J^T is singular; an undamped system that
    is singular too gives a meaningless step, not an error: callers skip the rows they do not move,
    such as a one-joint finger's at a singular posture). 3x3 systems are
    solved in closed form (:func:`solve3_symmetric`) for large batches.
    """
    k, n = J.shape[-2], J.shape[-1]
    Jt = J.transpose(-1, -2)
    if n < k:
        A = Jt @ J
        _add_damping(A, damping)
        return torch.linalg.solve_ex(A, (Jt @ err.unsqueeze(-1)))[0].squeeze(-1)  # a singular system: no raise
    A = J @ Jt
    _add_damping(A, damping)
    if k != 3 or A.numel() <= SMALL_BATCH * 9:  # LAPACK is faster for a handful of 3x3 systems, the adjugate for many
        y = torch.linalg.solve_ex(A, err)[0]
    else:
        y = solve3_symmetric(A, err)
    return (Jt @ y.unsqueeze(-1)).squeeze(-1)


def _add_damping(A: Tensor, damping: float | Tensor) -> None:
    """A (..., k, k) += damping^2 I, in place (a tensor damping: one lambda per system)."""
    if isinstance(damping, Tensor):
        A.diagonal(dim1=-2, dim2=-1).add_((damping * damping).unsqueeze(-1))
    elif damping:
        A.diagonal(dim1=-2, dim2=-1).add_(damping * damping)


def limited_step(J: Tensor, err: Tensor, q: Tensor, lower: Tensor, upper: Tensor, damping: float) -> Tensor:
    """A damped pseudo-inverse step that respects joint limits by re-solving, not just clamping.

    A joint that sits at a limit and that the error would push further out (the sign of
    ``(J^T err)_j``, the steepest-descent direction) is locked: its Jacobian column is zeroed and the
    step solved with the other joints, which a redundant chain can usually use to make the full
    Cartesian correction, where a plain clamp would stall against the limit (an active-set step).
    Joints that cross a limit during the step are clamped, and locked at the next step. Returns the
    new posture, within limits.

    J: (..., 3, n); err: (..., 3); q: (..., n); lower, upper: broadcastable to q -> (..., n).
    """
    g = (J.transpose(-1, -2) @ err.unsqueeze(-1)).squeeze(-1)
    lock = ((q <= lower) & (g < 0)) | ((q >= upper) & (g > 0))
    dq = damped_pinv_step(J.masked_fill(lock.unsqueeze(-2), 0.0), err, damping)
    return torch.clamp(q + dq, lower, upper)


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
