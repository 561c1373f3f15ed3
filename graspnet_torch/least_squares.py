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
(an active set; ``LMOptions(active_set=False)``: the step is only clamped to the bounds). A step is kept
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

__all__ = ["LMOptions", "LMResult", "Model", "Prior", "damped_pinv_step", "frame_model", "levenberg_marquardt",
           "numerical_jacobian", "solve3_symmetric"]

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


@dataclass(frozen=True)
class LMOptions:
    """How :func:`levenberg_marquardt` damps, when its rows stop and what it records.

    Attributes:
        lam, lam_min, lam_max: the damping's start and range (lam_min = lam_max: a fixed damping).
        edge: a value within this of a bound counts as at it.
        tol: a row stops once |e| < tol.
        min_gain: a row whose kept step lowered |e| by less than this fraction of it has settled
            (a local minimum above ``tol``) and stops: its last steps gain nothing worth their cost.
        active_set: joints at a bound that the step pushes outward leave the Jacobian and the step
            is solved again; False: the step is only clamped to the bounds.
        converged: ``converged(e (B, k))`` -> (B,) bool, the rows that have converged, in place of
            ``|e| < tol`` (a model whose residuals have different scales: some must vanish, others
            only be small).
        count: ``count(x, rows)`` -> (b,) collisions; a step may not raise it.
        done: ``done(converged (B,) bool)`` -> (B,) bool, the rows that stop (at least the
            converged ones; e.g. every row of a problem with enough converged rows).
        trace: a list that receives |e| (B,) after every step (curves for TensorBoard).
    """

    lam: float = 1e-3
    lam_min: float = 1e-6
    lam_max: float = 1.0
    edge: float = 1e-12
    tol: float = 0.0
    min_gain: float = 0.0
    active_set: bool = True
    converged: Callable[[Tensor], Tensor] | None = None
    count: Callable[[Tensor, Tensor], Tensor] | None = None
    done: Callable[[Tensor], Tensor] | None = None
    trace: list[Tensor] | None = None


@dataclass(frozen=True)
class Prior:
    """A residual term toward a centre: ``weight * (x - centre)``, m residuals appended to a
    model's (Jacobian rows diag(weight)), their goal 0: among the x that fit the goal, one nearer
    the centre. centre: (m,) or (B, m); weight: (m,)."""

    centre: Tensor
    weight: Tensor

    def appended(self, f: Model, goal: Tensor) -> tuple[Model, Tensor]:
        """The model with this term's m residuals appended and the goal (B, k) with m zeros
        appended: (B, k + m)."""
        B, m = goal.shape[0], self.weight.shape[0]
        centre, weight = self.centre.expand(B, m), self.weight
        tikhonov = torch.diag(weight)

        def with_prior(xx: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
            v, J = f(xx, rows)
            return (torch.cat([v, weight * (xx - centre[rows])], 1),
                    torch.cat([J, tikhonov.expand(xx.shape[0], m, m)], 1))

        return with_prior, torch.cat([goal, goal.new_zeros(B, m)], 1)


def levenberg_marquardt(f: Model, goal: Tensor, x: Tensor, lo: Tensor, hi: Tensor, iterations: int,
                        options: LMOptions = LMOptions(), prior: Prior | None = None) -> LMResult:
    """Levenberg-Marquardt on B rows (float64, the device of ``x``).

    Args:
        f: the model (:data:`Model`): ``f(x, rows)`` -> value (b, k), Jacobian (b, k, m) of the
            rows ``rows`` (b,) (indices into the batch). Rows may come in any subset; f must not
            depend on which (except through ``rows``).
        goal: (B, k) or (k,).
        x: (B, m) start, clamped to the bounds first.
        lo, hi: (m,) or (B, m) bounds.
        iterations: most steps per row.
        options: the damping, the stopping rules, the collision count and the trace (:class:`LMOptions`).
        prior: a residual term toward a centre (:class:`Prior`), appended to the model's; the
            result's ``err`` and ``value`` are the model's alone.
    """
    o = options
    B, m = x.shape
    goal = goal.expand(B, -1) if goal.dim() == 1 else goal
    k = goal.shape[1]
    if prior is not None:
        f, goal = prior.appended(f, goal)
    lo, hi = (b.expand(B, m) if b.dim() == 1 else b for b in (lo, hi))
    x = torch.minimum(torch.maximum(x, lo), hi).clone()
    all_rows = torch.arange(B, device=x.device)
    s = _first_state(f, o.count, goal, x, all_rows, o.lam)
    checks = o.tol > 0 or o.done is not None or o.converged is not None  # else only a settled row stops
    fixed = o.lam == o.lam_min == o.lam_max  # a fixed damping: lambda never changes
    for it in range(iterations):
        stopped = _stopped(s, goal, o.tol, o.converged, o.done) if checks else s.settled
        chosen = _rows_to_step(stopped, s.stalled, all_rows)
        if chosen is None:  # every row stopped, or nothing changes any more: the rows run the budget out
            if not bool(stopped.all()):
                s.steps += (~stopped).long() * (iterations - it)
                if o.trace is not None:
                    o.trace.extend(s.err.clone() for _ in range(iterations - it))
            break
        rows, ids, running = chosen
        part = _Rows(s.x[rows], s.value[rows], s.jac[rows], goal[rows], lo[rows], hi[rows], s.lams[rows])
        dx = _damped_step(part, o.edge, o.active_set)
        _accept_or_reject(f, o.count, s, part, rows, ids, dx, min_gain=o.min_gain, lam_min=o.lam_min,
                          lam_max=o.lam_max, fixed=fixed)
        s.steps += 1 if running is None else running.long()  # a stalled row counts the steps it would repeat
        if o.trace is not None:
            o.trace.append(s.err.clone())
    value, err = s.value, s.err
    if prior is not None:  # the model's residuals alone
        value = value[:, :k]
        err = (goal[:, :k] - value).norm(dim=-1)
    return LMResult(x=s.x, err=err, value=value, count=s.counts, steps=s.steps)


@dataclass
class _LMState:
    """Every row's state during :func:`levenberg_marquardt`, updated in place by its steps.

    Attributes:
        x: (B, m) the configurations.
        value: (B, k) f(x); jac: (B, k, m) its Jacobian.
        err: (B,) |g - f(x)|.
        lams: (B,) each row's damping lambda.
        counts: (B,) the collision count at x, or None without a count.
        steps: (B,) iterations each row has run.
        stalled: (B,) bool: the row's step was refused at lambda = lam_max (it would be refused again).
        settled: (B,) bool: the row's kept step gained less than ``min_gain``.
    """

    x: Tensor
    value: Tensor
    jac: Tensor
    err: Tensor
    lams: Tensor
    counts: Tensor | None
    steps: Tensor
    stalled: Tensor
    settled: Tensor


def _first_state(f: Model, count: Callable[[Tensor, Tensor], Tensor] | None, goal: Tensor, x: Tensor,
                 all_rows: Tensor, lam: float) -> _LMState:
    """Every row at its start x (B, m): the model's value and Jacobian there, |e|, the damping
    ``lam``, the collision count, no steps yet."""
    B = x.shape[0]
    value, jac = f(x, all_rows)
    value, jac = value.clone(), jac.clone()
    err = (goal - value).norm(dim=-1)
    lams = torch.full((B,), lam, dtype=x.dtype, device=x.device)
    counts = count(x, all_rows) if count is not None else None
    steps = torch.zeros(B, dtype=torch.long, device=x.device)
    stalled = torch.zeros(B, dtype=torch.bool, device=x.device)
    settled = torch.zeros(B, dtype=torch.bool, device=x.device)
    return _LMState(x=x, value=value, jac=jac, err=err, lams=lams, counts=counts, steps=steps, stalled=stalled,
                    settled=settled)


def _stopped(s: _LMState, goal: Tensor, tol: float, converged: Callable[[Tensor], Tensor] | None,
             done: Callable[[Tensor], Tensor] | None) -> Tensor:
    """(B,) bool: the rows that stop: converged (|e| < tol, or ``converged``), those ``done``
    adds, and the settled ones."""
    stopped = s.err < tol if converged is None else converged(goal - s.value)
    if done is not None:
        stopped = stopped | done(stopped)
    return stopped | s.settled


def _rows_to_step(stopped: Tensor, stalled: Tensor, all_rows: Tensor
                  ) -> tuple[slice | Tensor, Tensor, Tensor | None] | None:
    """The rows this step moves (neither stopped nor stalled; stopped, stalled: (B,) bool): their
    index into the batch (a slice when every row moves: views of the whole tensors, no gather and
    scatter), their indices (b,), and the rows still running (B,) bool (None: every row); None
    when no row moves."""
    moving = ~(stopped | stalled)
    if bool(moving.all()):
        return slice(None), all_rows, None
    if not bool(moving.any()):
        return None
    ids = moving.nonzero().squeeze(1)
    return ids, ids, ~stopped


@dataclass
class _Rows:
    """The rows one step moves (b of them; views of the whole tensors when every row moves):
    x (b, m), value (b, k), jac (b, k, m), goal (b, k), bounds lo, hi (b, m), damping (b,)."""

    x: Tensor
    value: Tensor
    jac: Tensor
    goal: Tensor
    lo: Tensor
    hi: Tensor
    damping: Tensor


def _damped_step(r: _Rows, edge: float, active_set: bool) -> Tensor:
    """The damped step dx (b, m) of the rows ``r`` at their damping; with ``active_set``, the joints
    at a bound that it pushes outward leave the Jacobian and their rows' step is solved again."""
    e = r.goal - r.value
    dx = damped_pinv_step(r.jac, e, r.damping)
    if active_set:
        blocked = ((r.x <= r.lo + edge) & (dx < 0)) | ((r.x >= r.hi - edge) & (dx > 0))
        again = blocked.any(1).nonzero().squeeze(1)
    if active_set and again.numel():  # joints at a bound the step pushes outward leave the Jacobian
        dx = dx.index_copy(0, again, damped_pinv_step(r.jac[again] * (~blocked[again]).unsqueeze(1), e[again],
                                                      r.damping[again]))
    return dx


def _accept_or_reject(f: Model, count: Callable[[Tensor, Tensor], Tensor] | None, s: _LMState, r: _Rows,
                      rows: slice | Tensor, ids: Tensor, dx: Tensor, *, min_gain: float, lam_min: float,
                      lam_max: float, fixed: bool) -> None:
    """Evaluate the rows ``r`` (at ``rows`` of the batch, indices ``ids`` (b,)) at x + dx within
    their bounds and keep each trial point where it lowers |e| (and does not raise the collision
    count): then lambda / 3, else lambda * 4, within [lam_min, lam_max]; marks the settled rows
    and the stalled ones (refused at lam_max)."""
    new = torch.minimum(torch.maximum(r.x + dx, r.lo), r.hi)
    new_value, new_jac = f(new, ids)
    new_err = (r.goal - new_value).norm(dim=-1)
    better = new_err < s.err[rows]
    if s.counts is not None:  # never into a collision: a step may not raise the count
        new_count = count(new, ids)
        better &= new_count <= s.counts[rows]
        s.counts[rows] = torch.where(better, new_count, s.counts[rows])
    s.x[rows] = torch.where(better.unsqueeze(1), new, r.x)
    s.value[rows] = torch.where(better.unsqueeze(1), new_value, r.value)
    s.jac[rows] = torch.where(better.view(-1, 1, 1), new_jac, r.jac)
    if min_gain > 0:
        s.settled[rows] = better & (new_err > s.err[rows] * (1 - min_gain))
    s.err[rows] = torch.where(better, new_err, s.err[rows])
    s.stalled[rows] = ~better & (r.damping >= lam_max)  # the same step again next time: rejected again
    if not fixed:
        s.lams[rows] = torch.where(better, r.damping / 3, r.damping * 4).clamp(lam_min, lam_max)
