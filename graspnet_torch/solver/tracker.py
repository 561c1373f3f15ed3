"""Best-so-far, R3/R4 rescoring and stopping per trial and per problem: one tracker for every search.

The SRV loop (``solver/loop.py``) and CMA-ES (``solver/cmaes.py``) see the same (possibly noisy)
reinforcement and keep, per trial, the configuration with the highest *observed* reinforcement.
Under R3/R4 the collision shaping grows with the iteration i (eq. 22-23), so the kept one is
rescored as it would be now (its noise draw kept): an early colliding configuration does not outrank
later clear ones. A trial stops at its own success; a problem (``problem_index``) ends once
``stop`` of its trials have succeeded, its other trials with it.
"""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.rewards import Reward
from graspnet_torch.solver.environment import Evaluation

__all__ = ["Tracker", "enough_succeeded"]


def enough_succeeded(succeeded: Tensor, problem_index: Tensor | None, stop: int) -> Tensor:
    """(T,) True for the trials of problems with at least ``stop`` successes (``problem_index``
    (T,): each trial's problem; None: one problem)."""
    if problem_index is None:
        return succeeded.sum().expand(succeeded.shape[0]) >= stop
    counts = torch.zeros(int(problem_index.max()) + 1, dtype=torch.long, device=succeeded.device)
    counts.index_add_(0, problem_index, succeeded.long())
    return counts[problem_index] >= stop


class Tracker:
    """T trials' best-so-far and stopping state.

    Attributes:
        config: (T, n) each trial's kept configuration (in the search's own units), or None before
            the first offer.
        evaluation: its evaluation; ``r``: (T,) its noise-free reinforcement; ``observed``: (T,)
            the reinforcement it was kept for (with the noise draw).
        active: (T,) trials still searching; ``succeeded``: (T,) trials that met their rule.
        iterations: (T,) the iteration each trial stopped at (the budget until it stops).
        all_active: no trial has stopped yet (the searches' fast path).
    """

    def __init__(self, trials: int, reward: Reward, budget: int, problem_index: Tensor | None = None,
                 stop: int | None = None, device: torch.device | str = "cpu"):
        self.reward, self.problem_index, self.stop = reward, problem_index, stop
        self.active = torch.ones(trials, dtype=torch.bool, device=device)
        self.succeeded = torch.zeros(trials, dtype=torch.bool, device=device)
        self.iterations = torch.full((trials,), budget, dtype=torch.long, device=device)
        self.all_active = True
        self.n_active = trials
        self.config: Tensor | None = None
        self.evaluation: Evaluation | None = None
        self.r: Tensor | None = None
        self.observed: Tensor | None = None
        self._forgotten: Tensor | None = None

    def rescore(self, iteration: int | Tensor) -> None:
        """R3/R4 with collision counts: the kept configurations scored as they would be at ``iteration``."""
        ev = self.evaluation
        if ev is not None and ev.collisions is not None and self.reward.cfg.kind in ("r3", "r4"):
            rescored = self.reward(ev, iteration).to(self.r)
            self.observed, self.r = self.observed + (rescored - self.r), rescored

    def offer(self, config: Tensor, evaluation: Evaluation, r: Tensor, observed: Tensor,
              better: Tensor | None = None) -> None:
        """Every trial's new configuration (T, n), its evaluation and reinforcement (T,): kept where
        ``better`` (default: observed above the kept one's) and the trial is active; the first
        offer is kept whole."""
        if self.config is None:
            self.config, self.evaluation, self.r, self.observed = config, evaluation, r, observed
            return
        if better is None:
            better = observed > self.observed
        if self._forgotten is not None:  # trials whose kept configuration was refused: any offer replaces it
            better, self._forgotten = better | self._forgotten, None
        if not self.all_active:
            better = better & self.active
        self.observed = torch.where(better, observed, self.observed)
        self.r = torch.where(better, r, self.r)
        self.config = torch.where(better.unsqueeze(1), config, self.config)
        self.evaluation = evaluation.where(better, self.evaluation)

    def offer_rows(self, trials: Tensor, config: Tensor, evaluation: Evaluation, r: Tensor, observed: Tensor
                   ) -> None:
        """Some trials' (B,) new configurations (B, n), evaluations and reinforcements (B,): kept
        where their observed reinforcement beats the kept one's. Needs a first whole :meth:`offer`
        (or a start: :meth:`start`)."""
        better = observed.to(self.observed) > self.observed[trials]
        self.observed[trials] = torch.where(better, observed.to(self.observed), self.observed[trials])
        self.r[trials] = torch.where(better, r.to(self.r), self.r[trials])
        self.config[trials] = torch.where(better.unsqueeze(1), config.to(self.config), self.config[trials])
        if self.evaluation is None:  # the first rows offered are every trial's
            self.evaluation = evaluation.clone()
            return
        take = trials[better]
        self.evaluation = Evaluation(**{
            name: mine.index_copy(0, take.to(mine.device), getattr(evaluation, name)[better.to(mine.device)])
            for name, mine in self.evaluation.tensors().items()})

    def start(self, config: Tensor, dtype: torch.dtype = torch.float64) -> None:
        """Start from configurations (T, n) kept at reinforcement -inf (any first offer beats them)."""
        T = config.shape[0]
        self.config = config.clone()
        self.r = torch.full((T,), -float("inf"), dtype=dtype, device=config.device)
        self.observed = self.r.clone()

    def forget(self, trials: Tensor) -> None:
        """The kept configurations of ``trials`` (T,) bool are no longer worth keeping (a grasp the
        exact collision check refused): the next :meth:`offer` replaces them whatever it brings."""
        self._forgotten = trials if self._forgotten is None else self._forgotten | trials

    def finish(self, done: Tensor, at: int | Tensor) -> bool:
        """The trials ``done`` (T,) have succeeded at iteration ``at`` (an int, or (T,)): they stop,
        and with ``stop``, so do the other trials of problems with enough successes (at ``at``).
        Returns whether any trial is still active."""
        self.succeeded |= done
        if self.stop is not None:  # a problem with enough successes ends: its other trials too
            done = done | (self.active & enough_succeeded(self.succeeded, self.problem_index, self.stop))
        at = torch.full_like(self.iterations, at) if isinstance(at, int) else at.to(self.iterations)
        self.iterations = torch.where(done, at, self.iterations)
        self.active = self.active & ~done
        self.all_active = False
        self.n_active = int(self.active.sum())
        return self.n_active > 0

    def halt(self, at: int) -> None:
        """Out of time at iteration ``at``: the active trials stop there."""
        self.iterations = torch.where(self.active, torch.full_like(self.iterations, at), self.iterations)
