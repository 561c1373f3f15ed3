"""The rows the SRV loop (:mod:`graspnet_torch.solver.loop`) runs on: every trial's until most
trials have stopped, then only the trials still running (their tracker, bounds, sensor noise and
evaluation follow them), so that the late iterations of a few stragglers cost only their rows."""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.rewards import add_noise
from graspnet_torch.solver.environment import Environment, Evaluation
from graspnet_torch.solver.tracker import Tracker

__all__ = ["RunningRows", "spread_rows", "take_rows"]


def take_rows(ev: Evaluation, rows: Tensor) -> Evaluation:
    """The evaluation of the rows ``rows`` (R,) of ``ev``."""
    return Evaluation(**{k: v[rows.to(v.device)] for k, v in ev.tensors().items()})


def spread_rows(value: Tensor, rows: Tensor, trials: int) -> Tensor:
    """(T, ...) zeros but for the rows ``rows`` (R,): ``value`` (R, ...)."""
    return value.new_zeros((trials, *value.shape[1:])).index_copy(0, rows.to(value.device), value)


class RunningRows:
    """The rows a loop runs on: every trial's (:attr:`rows` None, T rows) until most trials have
    stopped, then only those of the trials :attr:`rows` (R,) (sorted), the ones still active when
    the loop last compacted (:meth:`select`) and which it keeps running. Their tracker is a part
    of every trial's (:meth:`Tracker.part`), handed back by :meth:`whole`; per-trial bounds,
    sensor noise and an environment that evaluates every trial at once follow the rows."""

    def __init__(self, env: Environment, trials: int, span: Tensor):
        self.env, self.trials, self._span = env, trials, span
        self.rows: Tensor | None = None
        self.lower, self.span = env.lower, span  # (n,) or the rows' (R, n)
        self._every: Tracker | None = None  # every trial's tracker, once the loop runs on some rows
        self._o: Tensor | None = None  # (T, n) every trial's last output, for an environment without subsets

    def select(self, keep: Tensor, best: Tracker, o_prev: Tensor) -> Tracker:
        """From now on run on the rows ``keep`` (R,) of the current ones, whose tracker is ``best``
        and last outputs ``o_prev``; returns the tracker of the rows kept."""
        rows = keep if self.rows is None else self.rows[keep]
        if not self.env.subsets:  # the trials dropped now keep their last output
            self._o = o_prev if self.rows is None else self._o.index_copy(0, self.rows, o_prev)
        if self.rows is None:
            self._every = best
        else:
            self._every.absorb(best, self.rows)
        if self.env.lower.dim() > 1:
            self.lower, self.span = self.env.lower[rows], self._span[rows]
        self.rows = rows
        return self._every.part(rows)

    def whole(self, best: Tracker) -> Tracker:
        """Every trial's tracker, given the tracker ``best`` of the current rows."""
        if self.rows is None:
            return best
        self._every.absorb(best, self.rows)
        return self._every

    def evaluate(self, o: Tensor) -> Evaluation:
        """The rows' evaluation of their outputs ``o`` (R, n), for an environment that evaluates
        every trial at once (no subsets): the others at their last outputs."""
        ev = self.env.evaluate(torch.addcmul(self.env.lower, self._span, self._o.index_copy(0, self.rows, o)))
        return take_rows(ev, self.rows)

    def observe(self, r: Tensor, sigma: float, gen: torch.Generator) -> Tensor:
        """The observed reinforcement (R,) of the rows' ``r`` (eq. 15): every trial's noise drawn."""
        if self.rows is None or sigma <= 0:
            return add_noise(r, sigma, gen)
        return r + sigma * torch.randn(self.trials, generator=gen, dtype=r.dtype, device=r.device)[self.rows]

    def confirm(self, best: Tracker, idx: Tensor) -> Tensor:
        """:meth:`Environment.confirm` of the rows ``idx`` (B,) of the tracker ``best``."""
        if self.rows is None:
            return self.env.confirm(best.config, best.evaluation, idx)
        trials = self.rows[idx]
        ev = Evaluation(**{k: spread_rows(v[idx.to(v.device)], trials, self.trials)
                           for k, v in best.evaluation.tensors().items()})
        return self.env.confirm(spread_rows(best.config[idx], trials, self.trials), ev, trials)
