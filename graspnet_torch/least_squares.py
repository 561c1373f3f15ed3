"""The package's one damped-least-squares step and its one Levenberg-Marquardt: batched, within bounds.

Every least-squares loop of the package is a residual function handed to
:func:`levenberg_marquardt`: fingertip positions (``solver=dls``, a hand's polish, ``robot/ik.refine``),
a gripper's points (its settling steps and polish), two fingertips brought together
(``jobs/inspect_robots``), a reference posture's contacts with a prior toward mid-range
(``solver/reference_fit``); a palm or gripper frame, or a back-off target (the frame moved away,
its orientation kept), is a model of the same kind (value: position and rotation error, Jacobian:
the frame's). The FCNN's refinement (paper eq. 5, ``fcnn/ik.py``) keeps its own steps: the
paper's method. Only torch: the utilities layer, so every layer above may use it.

For B rows at once, each with its own goal, bounds and damping, minimise |g - f(x)| over x within
[lo, hi], with the model's analytic Jacobian:

    e = g - f(x)                              (B, k)
    J = d f / d x                             (B, k, m), given by the model with its value
    dx = J^T (J J^T + lambda^2 I)^-1 e        (:func:`damped_pinv_step`, the package's one step)

Joints at a bound that the step pushes outward leave the Jacobian and the step is solved again
(an active set; ``active_set=False``: the step is only clamped to the bounds). A step is kept
only where it lowers |e| and, with a collision count, does not raise it: never worse. Kept:
lambda / 3, else lambda * 4, within [lam_min, lam_max] (lam_min = lam_max: a fixed damping). A
row stops once |e| < ``tol``, once ``done`` says so (e.g. enough rows of its problem have
converged), or once a kept step gains less than ``min_gain`` of |e| (settled in a local
minimum), and then costs nothing more. A row whose step was refused at lambda = lam_max would
take the very same step again (same x, Jacobian and damping) and be refused again: it is not evaluated any more (its
steps still count, as if it ran them), and once every running row is such, the call ends.

The model returns its value and Jacobian together, and the trial point's Jacobian is the next
step's when the step is kept: a step costs one model evaluation. :func:`numerical_jacobian`
(forward differences, m + 1 evaluations) is the oracle the analytic Jacobians are tested against.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["LMResult", "Model", "damped_pinv_step", "frame_model", "levenberg_marquardt", "numerical_jacobian",
           "solve3_symmetric"]

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

Model = Callable[[Tensor, Tensor], tuple[Tensor, Tensor]]
"""``f(x, rows)``: x (b, m) of the rows ``rows`` (b,) -> value (b, k) and Jacobian d value / d x (b, k, m)."""


@dataclass
class LMResult:
    """Where each row ended.

    Attributes:
        x: (B, m) the configurations.
        err: (B,) |g - f(x)|.
        value: (B, k) f(x).
        count: (B,) the collision count at x, or None without a count.
        steps: (B,) iterations each row ran before it stopped (its tolerance, or the budget).
    """

    x: Tensor
    err: Tensor
    value: Tensor
    count: Tensor | None
    steps: Tensor


def numerical_jacobian(f: Callable[[Tensor], Tensor], x: Tensor, h: float = 1e-7) -> Tensor:
    """Forward differences (f(x + h e_i) - f(x)) / h: f maps x (b, m) -> (b, k); returns (b, k, m).
    m + 1 evaluations of f (one batch of b (m + 1) rows): the oracle of the analytic Jacobians."""
    b, m = x.shape
    shifted = torch.cat([x.unsqueeze(1), x.unsqueeze(1) + h * torch.eye(m, dtype=x.dtype, device=x.device)], 1)
    values = f(shifted.reshape(-1, m)).reshape(b, m + 1, -1)
    return ((values[:, 1:] - values[:, :1]) / h).transpose(1, 2)


def frame_model(frame_jacobian: Callable[[Tensor], tuple[Tensor, Tensor, Tensor]], rotation: Tensor) -> Model:
    """A frame's residual (a palm's or a gripper's; a back-off target: the frame moved, its
    orientation kept) as a :data:`Model`: with ``goal = [t_goal, 0, 0, 0]``, g - f(x) is the
    position error t_goal - t and the rotation error w = vee(R_goal R^T - R R_goal^T) / 2 (small
    angles: the angular rows of the geometric Jacobian are its Jacobian, up to sign).

    frame_jacobian: x (b, m) -> R (b, 3, 3), t (b, 3), J (b, 6, m) (rows d t, then the angular
    velocity; e.g. ``Robot.palm_frame_jacobian``); rotation: R_goal (3, 3) or (B, 3, 3).
    """

    def frame(x: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
        R, t, J = frame_jacobian(x)
        goal = rotation if rotation.dim() == 2 else rotation[rows]
        E = goal @ R.transpose(-1, -2)
        w = 0.5 * torch.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], -1)
        return torch.cat([t, -w], -1), J

    return frame


def levenberg_marquardt(f: Model, goal: Tensor, x: Tensor, lo: Tensor, hi: Tensor, iterations: int, *,
                        lam: float = 1e-3, lam_min: float = 1e-6, lam_max: float = 1.0, edge: float = 1e-12,
                        tol: float = 0.0, min_gain: float = 0.0, active_set: bool = True,
                        converged: Callable[[Tensor], Tensor] | None = None,
                        count: Callable[[Tensor, Tensor], Tensor] | None = None,
                        done: Callable[[Tensor], Tensor] | None = None, trace: list[Tensor] | None = None,
                        prior: tuple[Tensor, Tensor] | None = None) -> LMResult:
    """Levenberg-Marquardt on B rows (float64, the device of ``x``).

    Args:
        f: the model (:data:`Model`): ``f(x, rows)`` -> value (b, k), Jacobian (b, k, m) of the
            rows ``rows`` (b,) (indices into the batch). Rows may come in any subset; f must not
            depend on which (except through ``rows``).
        goal: (B, k) or (k,).
        x: (B, m) start, clamped to the bounds first.
        lo, hi: (m,) or (B, m) bounds.
        iterations: most steps per row.
        lam, lam_min, lam_max: the damping's start and range.
        edge: a value within this of a bound counts as at it.
        active_set: joints at a bound that the step pushes outward leave the Jacobian and the step
            is solved again; False: the step is only clamped to the bounds.
        tol: a row stops once |e| < tol.
        converged: ``converged(e (B, k))`` -> (B,) bool, the rows that have converged, in place of
            ``|e| < tol`` (a model whose residuals have different scales: some must vanish, others
            only be small).
        min_gain: a row whose kept step lowered |e| by less than this fraction of it has settled
            (a local minimum above ``tol``) and stops: its last steps gain nothing worth their cost.
        count: ``count(x, rows)`` -> (b,) collisions; a step may not raise it.
        done: ``done(converged (B,) bool)`` -> (B,) bool, the rows that stop (at least the
            converged ones; e.g. every row of a problem with enough converged rows).
        trace: a list that receives |e| (B,) after every step (curves for TensorBoard).
        prior: (centre (m,) or (B, m), weight (m,)): also minimise |weight * (x - centre)|, m
            residuals appended to the model's (the result's ``err`` and ``value`` are the model's
            alone): among the x that fit the goal, one nearer the centre.
    """
    B, m = x.shape
    goal = goal.expand(B, -1) if goal.dim() == 1 else goal
    if prior is not None:
        k, model = goal.shape[1], f
        centre, weight = prior[0].expand(B, m), prior[1]
        tikhonov = torch.diag(weight)

        def f(xx: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
            v, J = model(xx, rows)
            return (torch.cat([v, weight * (xx - centre[rows])], 1),
                    torch.cat([J, tikhonov.expand(xx.shape[0], m, m)], 1))

        goal = torch.cat([goal, goal.new_zeros(B, m)], 1)
    lo, hi = (b.expand(B, m) if b.dim() == 1 else b for b in (lo, hi))
    x = torch.minimum(torch.maximum(x, lo), hi).clone()
    all_rows = torch.arange(B, device=x.device)
    value, jac = f(x, all_rows)
    value, jac = value.clone(), jac.clone()
    err = (goal - value).norm(dim=-1)
    lams = torch.full((B,), lam, dtype=x.dtype, device=x.device)
    counts = count(x, all_rows) if count is not None else None
    steps = torch.zeros(B, dtype=torch.long, device=x.device)
    stalled = torch.zeros(B, dtype=torch.bool, device=x.device)
    settled = torch.zeros(B, dtype=torch.bool, device=x.device)
    checks = tol > 0 or done is not None or converged is not None  # else only a settled row stops
    fixed = lam == lam_min == lam_max  # a fixed damping: lambda never changes
    for it in range(iterations):
        stopped = settled
        if checks:
            stopped = err < tol if converged is None else converged(goal - value)
            if done is not None:
                stopped = stopped | done(stopped)
            stopped = stopped | settled
        moving = ~(stopped | stalled)
        running = None  # every row
        if bool(moving.all()):  # every row: views of the whole tensors, no gather and scatter
            rows, ids = slice(None), all_rows
        else:
            if bool(stopped.all()):
                break
            running = ~stopped
            if not bool(moving.any()):  # nothing changes any more: the rows ran the budget out
                steps += running.long() * (iterations - it)
                if trace is not None:
                    trace.extend(err.clone() for _ in range(iterations - it))
                break
            rows = ids = moving.nonzero().squeeze(1)
        xr, vr, Jr, gr, lr, hr = x[rows], value[rows], jac[rows], goal[rows], lo[rows], hi[rows]
        e = gr - vr
        damping = lams[rows]
        dx = damped_pinv_step(Jr, e, damping)
        if active_set:
            blocked = ((xr <= lr + edge) & (dx < 0)) | ((xr >= hr - edge) & (dx > 0))
            again = blocked.any(1).nonzero().squeeze(1)
        if active_set and again.numel():  # joints at a bound the step pushes outward leave the Jacobian
            dx = dx.index_copy(0, again, damped_pinv_step(Jr[again] * (~blocked[again]).unsqueeze(1), e[again],
                                                          damping[again]))
        new = torch.minimum(torch.maximum(xr + dx, lr), hr)
        new_value, new_jac = f(new, ids)
        new_err = (gr - new_value).norm(dim=-1)
        better = new_err < err[rows]
        if counts is not None:  # never into a collision: a step may not raise the count
            new_count = count(new, ids)
            better &= new_count <= counts[rows]
            counts[rows] = torch.where(better, new_count, counts[rows])
        x[rows] = torch.where(better.unsqueeze(1), new, xr)
        value[rows] = torch.where(better.unsqueeze(1), new_value, vr)
        jac[rows] = torch.where(better.view(-1, 1, 1), new_jac, Jr)
        if min_gain > 0:
            settled[rows] = better & (new_err > err[rows] * (1 - min_gain))
        err[rows] = torch.where(better, new_err, err[rows])
        stalled[rows] = ~better & (damping >= lam_max)  # the same step again next time: rejected again
        if not fixed:
            lams[rows] = torch.where(better, damping / 3, damping * 4).clamp(lam_min, lam_max)
        steps += 1 if running is None else running.long()  # a stalled row counts the steps it would repeat
        if trace is not None:
            trace.append(err.clone())
    if prior is not None:  # the model's residuals alone
        value = value[:, :k]
        err = (goal[:, :k] - value).norm(dim=-1)
    return LMResult(x=x, err=err, value=value, count=counts, steps=steps)
