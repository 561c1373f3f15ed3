"""Position-only IK with damped least squares (paper eq. 5 and 8): the FCNN's step within the
joint limits, and a refinement on the package's one Levenberg-Marquardt.

    theta(k+1) = theta(k) + J^+(theta(k)) (X_D - g(theta(k))),
    J^+ = J^T (J J^T + lambda^2 I)^-1        (damped least squares; lambda = 0 is eq. 5 exactly)

The step itself is :func:`graspnet_torch.least_squares.damped_pinv_step` (used here, and
importable from here for the callers that still do).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from graspnet_torch.least_squares import LMOptions, damped_pinv_step, frame_model, levenberg_marquardt

__all__ = ["frame_ik", "limited_step", "refine"]

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
    damping: float = 1e-2,
    damping_range: tuple[float, float] = (1e-6, 1e3),
    tol: float = 0.0,
) -> tuple[Tensor, Tensor]:
    """Position IK within the joint limits: the positions' residual handed to the package's one
    Levenberg-Marquardt (:func:`~graspnet_torch.least_squares.levenberg_marquardt`: a step kept
    only where it lowers the distance, the damping adapted, joints at a limit that the step pushes
    outward out of the step).

    Args:
        fk_jacobian: q (..., n) -> (p (..., 3), J (..., 3, n)), e.g. ``ChainKernel.position_jacobian``
            or ``Robot.fingertips_base_jacobian``; each position depends on its own row of q only.
        q: (..., n) start postures; targets: (..., 3); lower, upper: (n,) or broadcastable limits.
        iterations: most steps.
        damping: lambda's start (metres); ``damping_range``: its least and largest.
        tol: a row stops once within this of its target (metres; 0: the whole budget).
    Returns:
        q: (..., n) refined postures within limits; error: (...,) distance to the targets (m).
    """
    shape, n = q.shape, q.shape[-1]
    start = q.reshape(-1, n)
    B = start.shape[0]
    lo, hi = (torch.broadcast_to(b, shape).reshape(B, n) for b in (lower, upper))
    goal = torch.broadcast_to(targets, (*shape[:-1], 3)).reshape(B, 3)
    whole = torch.minimum(torch.maximum(start, lo), hi)  # every row valid: fk_jacobian may want them all

    def positions(x: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
        every = x.shape[0] == B
        p, J = fk_jacobian((x if every else whole.index_copy(0, rows, x)).view(shape))
        p, J = p.reshape(B, 3), J.reshape(B, 3, n)
        return (p, J) if every else (p[rows], J[rows])

    solved = levenberg_marquardt(positions, goal, start, lo, hi, iterations,
                                 LMOptions(lam=damping, lam_min=damping_range[0], lam_max=damping_range[1], tol=tol))
    return solved.x.view(shape), solved.err.view(shape[:-1])


def frame_ik(frame_jacobian: Callable[[Tensor], tuple[Tensor, Tensor, Tensor]], R_goal: Tensor, t_goal: Tensor,
             starts: Tensor, lower: Tensor, upper: Tensor, iterations: int = 100, tol: float = 1e-5,
             min_gain: float = 0.0) -> tuple[Tensor, Tensor, Tensor]:
    """Full-pose IK of a frame (an arm's palm) within the joint limits: each goal from K starts on
    the package's one Levenberg-Marquardt (:func:`~graspnet_torch.least_squares.frame_model`'s
    residual: the position error in metres, the rotation error in radians), the best start kept.

    frame_jacobian: x (b, m) -> R (b, 3, 3), t (b, 3), J (b, 6, m) (e.g. ``Robot.palm_frame_jacobian``);
    R_goal: (B, 3, 3); t_goal: (B, 3); starts: (B, K, m); lower, upper: (m,); ``min_gain``: a start
    whose step gains less than this share of its error has settled and stops (the least squares'
    ``min_gain``: an unreachable goal stops early).
    Returns q: (B, m), the position error (B,) (m) and the rotation error (B,) (rad, small angles).
    """
    B, K, m = starts.shape
    R = R_goal.repeat_interleave(K, 0)
    goal = torch.cat([t_goal.repeat_interleave(K, 0), t_goal.new_zeros(B * K, 3)], 1)
    solved = levenberg_marquardt(frame_model(frame_jacobian, R), goal, starts.reshape(B * K, m), lower, upper,
                                 iterations, LMOptions(tol=tol, min_gain=min_gain))
    e = (goal - solved.value).view(B, K, 6)
    pos, rot = e[..., :3].norm(dim=-1), e[..., 3:].norm(dim=-1)
    best = (pos + rot * 0.1).argmin(dim=1)  # a tenth of a metre per radian
    rows = torch.arange(B)
    return solved.x.view(B, K, m)[rows, best], pos[rows, best], rot[rows, best]
