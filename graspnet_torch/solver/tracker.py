"""Best-so-far, R3/R4 rescoring and stopping per trial and per problem: one tracker for every search.

The SRV loop (``solver/loop.py``) and CMA-ES (``solver/cmaes.py``) see the same (possibly noisy)
reinforcement and keep, per trial, the configuration with the highest *observed* reinforcement.
Under R3/R4 the collision shaping grows with the iteration i (eq. 22-23), so the kept one is
rescored as it would be now (its noise draw kept): an early colliding configuration does not outrank
later clear ones. A trial stops at its own success; a problem (``problem_index``) ends once
``stop`` of its trials have succeeded, its other trials with it. Once most trials have stopped, the
SRV loop runs on the others' rows only: a tracker of theirs (:meth:`Tracker.part`, handed back with
:meth:`Tracker.absorb`) and their per-iteration curves (:class:`Curves`).
"""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.rewards import Reward
from graspnet_torch.solver.environment import Evaluation

__all__ = ["Curves", "Tracker", "enough_succeeded"]


def enough_succeeded(succeeded: Tensor, problem_index: Tensor | None, stop: int, elsewhere: Tensor | None = None
                     ) -> Tensor:
    """(T,) True for the trials of problems with at least ``stop`` successes (``problem_index``
    (T,): each trial's problem; None: one problem). ``elsewhere``: (P,) per problem (one problem:
    (1,)), successes of trials not among these (the stopped trials of a compacted loop)."""
    if problem_index is None:
        total = succeeded.sum() if elsewhere is None else succeeded.sum() + elsewhere.sum()
        return total.expand(succeeded.shape[0]) >= stop
    counts = (torch.zeros(int(problem_index.max()) + 1, dtype=torch.long, device=succeeded.device)
              if elsewhere is None else elsewhere.clone())
    counts.index_add_(0, problem_index, succeeded.long())
    return counts[problem_index] >= stop


def _successes(succeeded: Tensor, problem_index: Tensor | None) -> Tensor:
    """(P,) successes per problem ((1,) for one problem) of (T,) ``succeeded``."""
    if problem_index is None:
        return succeeded.sum().view(1)
    counts = torch.zeros(int(problem_index.max()) + 1, dtype=torch.long, device=succeeded.device)
    return counts.index_add_(0, problem_index, succeeded.long())


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
        self._elsewhere: Tensor | None = None  # a part's: (P,) successes of the trials outside it

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
            done = done | (self.active & enough_succeeded(self.succeeded, self.problem_index, self.stop,
                                                          self._elsewhere))
        at = torch.full_like(self.iterations, at) if isinstance(at, int) else at.to(self.iterations)
        self.iterations = torch.where(done, at, self.iterations)
        self.active = self.active & ~done
        self.all_active = False
        self.n_active = int(self.active.sum())
        return self.n_active > 0

    def halt(self, at: int) -> None:
        """Out of time at iteration ``at``: the active trials stop there."""
        self.iterations = torch.where(self.active, torch.full_like(self.iterations, at), self.iterations)

    def part(self, rows: Tensor) -> Tracker:
        """The tracker of the trials ``rows`` (R,) (sorted indices into this one's T, after a first
        :meth:`offer`): their state copied, a problem's successes among the other trials still
        counting towards its stop. A loop whose other trials have stopped runs on it and hands it
        back with :meth:`absorb`."""
        out = Tracker.__new__(Tracker)
        out.reward, out.stop, out.all_active = self.reward, self.stop, False
        out.problem_index = None if self.problem_index is None else self.problem_index[rows]
        out.active, out.succeeded, out.iterations = self.active[rows], self.succeeded[rows], self.iterations[rows]
        out.n_active = int(out.active.sum())
        out.config, out.r, out.observed = self.config[rows], self.r[rows], self.observed[rows]
        out.evaluation = Evaluation(**{k: v[rows.to(v.device)] for k, v in self.evaluation.tensors().items()})
        out._forgotten = None if self._forgotten is None else self._forgotten[rows]
        out._elsewhere = None
        if self.stop is not None:
            outside = self.succeeded.index_fill(0, rows, False)
            out._elsewhere = _successes(outside, self.problem_index)
            if self._elsewhere is not None:
                out._elsewhere += self._elsewhere
        return out

    def absorb(self, part: Tracker, rows: Tensor) -> None:
        """Take back the state of ``part``, the tracker of the trials ``rows`` (R,) (:meth:`part`).
        An evaluation part the part's rows have lost (a polish that gives none) is dropped for every
        trial, as one tracker of all trials would have dropped it."""
        self.config = self.config.index_copy(0, rows, part.config)
        mine, theirs = self.evaluation.tensors(), part.evaluation.tensors()
        ev = {}
        for name, value in theirs.items():  # a configuration part gained (a polish's): the kept configurations'
            base = mine.get(name, self.config if name == "config" else None)
            if base is None:
                base = value.new_zeros((self.active.shape[0], *value.shape[1:]))
            ev[name] = base.index_copy(0, rows.to(base.device), value)
        self.evaluation = Evaluation(**ev)
        for name in ("r", "observed", "active", "succeeded", "iterations"):
            setattr(self, name, getattr(self, name).index_copy(0, rows, getattr(part, name)))
        self._forgotten = None if part._forgotten is None else \
            torch.zeros_like(self.active).index_copy(0, rows, part._forgotten)
        self.all_active = self.all_active and part.all_active
        self.n_active = int(self.active.sum())


class Curves:
    """The per-iteration curves of a loop (``solver.history``), recorded for the rows it runs:
    iteration k's values (R, ...) are those of the trials ``rows`` (R,) it ran then (None: all
    T). A trial's curve holds its value at its stop after it, so a trial no longer run needs no
    row: :meth:`tensors` assembles (K, T, ...)."""

    def __init__(self) -> None:
        self.values: dict[str, list[Tensor]] = {}
        self.spans: list[tuple[int, Tensor | None]] = []  # (first iteration, rows) of each run of iterations
        self.time: list[float] = []

    def add(self, rows: Tensor | None, elapsed: float, values: dict[str, Tensor | None]) -> None:
        """Iteration k's values (R, ...) of the trials ``rows``; ``elapsed``: seconds since the start."""
        if not self.spans or self.spans[-1][1] is not rows:
            self.spans.append((len(self.time), rows))
        for key, value in values.items():
            if value is not None:
                self.values.setdefault(key, []).append(value)
        self.time.append(elapsed)

    def tensors(self, iterations: Tensor) -> dict[str, Tensor] | None:
        """(K, T[, ...]) per key, each trial's curve held at its stop (``iterations`` (T,));
        'expected' and 'sigma' are means over the SRV units; 'time' (K,) seconds."""
        if not self.time:
            return None
        K = len(self.time)
        stop = iterations.clamp(max=K) - 1  # (T,) each trial's last iteration: it still ran there
        out = {key: self._assemble(values, stop, key in ("expected", "sigma")) for key, values in self.values.items()}
        out["time"] = torch.tensor(self.time, dtype=torch.float64)
        return out

    def _assemble(self, values: list[Tensor], stop: Tensor, mean: bool) -> Tensor:
        if len(self.spans) == 1 and self.spans[0][1] is None:  # every trial ran every iteration recorded
            v = torch.stack(values)  # (K, T, ...)
            v = v.mean(-1) if mean else v
            K, T = v.shape[:2]
            held = v[stop, torch.arange(T, device=v.device)]  # (T, ...): each trial's value at its stop
            after = (torch.arange(K, device=v.device).view(-1, 1) > stop).view(K, T, *([1] * (v.dim() - 2)))
            return torch.where(after, held, v)
        ends = [k for k, _ in self.spans[1:]] + [len(self.time)]
        parts = []
        for (k0, rows), k1 in zip(self.spans, ends, strict=True):
            v = torch.stack(values[k0:k1])  # (k1 - k0, R, ...)
            s = stop if rows is None else stop[rows]
            parts.append((k0, k1, rows, v.mean(-1) if mean else v, s))
        first = parts[0][3]
        T, rest = stop.shape[0], first.shape[2:]
        held = first.new_empty((T, *rest))  # each trial's value at its stop
        for k0, k1, rows, v, s in parts:
            at = ((s >= k0) & (s < k1)).nonzero().squeeze(1)
            held.index_copy_(0, at if rows is None else rows[at], v[s[at] - k0, at])
        out = first.new_empty((len(self.time), T, *rest))
        for k0, k1, rows, v, s in parts:
            after = (torch.arange(k0, k1, device=s.device).view(-1, 1) > s).view(k1 - k0, -1, *([1] * len(rest)))
            if rows is None:
                torch.where(after, held, v, out=out[k0:k1])
            else:  # the trials not run then had stopped: they hold
                out[k0:k1] = held
                out[k0:k1].index_copy_(1, rows, torch.where(after, held[rows], v))
        return out
