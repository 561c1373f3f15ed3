"""The closed loop of section 2.4, batched over T independent trials.

One iteration, for every trial at once:

    x = (c_k, c_k - c_{k-1})  ->  configuration network (BP, BP, SRV)  ->  o in [0, 1]^n
    c_{k+1} = c_min + (c_max - c_min) o                                              (13)
    environment: E (eq. 3), for the hand and the arm by the FCNN's finger joints, + collisions
    r = R_1..R_4 (eq. 14, 20-23),  r + N(0, sigma_n)  (15)  ->  SRV / BP updates  (16-19)

The configuration fed back (c_k, in normalised units) is the network's output o. The loop sees
only the observed reinforcement (noisy when sigma_n > 0): a trial stops once it exceeds the
threshold, and reports the configuration with the highest observed reinforcement (``report:
best``, the default; without noise that is the smallest error E) or its last one (``final``).
With sensor noise the observed signal crosses any threshold by chance, so noisy runs use a fixed
budget (``threshold: null``), as the paper's noise study does. Stopped trials keep their
configuration and stop learning while the others go on.
Randomness (initial weights, random starts within the bounds, exploration, sensor noise) flows from
one seeded generator.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.rewards import Reward
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.environment import Environment, Evaluation
from graspnet_torch.solver.rows import RunningRows, take_rows
from graspnet_torch.solver.tracker import Curves, Tracker, enough_succeeded
from graspnet_torch.srv.network import ConfigurationNetwork, SRVNetCfg

__all__ = ["LoopOutcome", "Starts", "enough_succeeded", "run_loop"]

# In a batch of at least DEFER_FROM trials (gt.solve_many), trials that come near a solution are
# polished together: once DEFER_ROWS are waiting, or every DEFER_EVERY iterations (a polish of a
# few rows costs about what one of a hundred does).
DEFER_FROM, DEFER_ROWS, DEFER_EVERY = 256, 32, 8
START_MARGIN = 1e-3  # a given start is kept this far (normalised) inside the bounds: the SRV output's logit is finite


@dataclass
class Starts:
    """Where the trials of a loop start (``solver.start: proposal``).

    Attributes:
        config: (T, n) configurations, in the search's units.
        given: (T,) bool: the trials that start at their row of ``config``; the others start at
            random within the bounds, as the paper's do (a proposal the environment finds
            colliding is no start).
    """

    config: Tensor
    given: Tensor


@dataclass
class LoopOutcome:
    """Per-trial results (leading dimension T) and optional per-iteration history (K, T[, ...]):
    'reinforcement' (noise-free), 'observed' (with sensor noise), 'expected' and 'sigma' (means
    over the SRV units), 'total' (the evaluation's error, metres), 'errors' (per finger, when the
    environment gives them), 'collisions' (when it counts them), 'time' (K,) seconds since the start.

    Attributes:
        config: (T, n) the reported configuration of each trial.
        evaluation: the environment's evaluation of it.
        reinforcement: (T,) noise-free reinforcement there.
        iterations: iterations each trial ran (its stop, or the budget).
        success: the trial met its stopping rule (a grasp in the model, or a reinforcement above
            the threshold: ``solver.stop_rule``).
        wall_time_s: the whole loop; per-iteration wall times are ``history['time']``.
        start: (T, n) each trial's random start within the bounds (for baselines on the same starts).
    """

    config: Tensor
    evaluation: Evaluation
    reinforcement: Tensor
    iterations: Tensor
    success: Tensor
    wall_time_s: float
    history: dict[str, Tensor] | None
    start: Tensor | None = None

    def split(self, runs: int) -> list[LoopOutcome]:
        """The outcomes of consecutive groups of ``runs`` trials (a batch of problems: one per
        problem, in order), each tensor split once (views)."""
        ev = {k: v.split(runs) for k, v in self.evaluation.tensors().items()}
        history = None
        if self.history is not None:  # time, iteration: (K,); the others (K, T, ...)
            history = {k: v if v.dim() == 1 else v.split(runs, dim=1) for k, v in self.history.items()}
        config, r, its, success = (v.split(runs) for v in (self.config, self.reinforcement, self.iterations,
                                                             self.success))
        start = None if self.start is None else self.start.split(runs)
        return [LoopOutcome(config=config[p], evaluation=Evaluation(**{k: v[p] for k, v in ev.items()}),
                            reinforcement=r[p], iterations=its[p], success=success[p], wall_time_s=self.wall_time_s,
                            history=None if history is None else {k: v if isinstance(v, Tensor) else v[p]
                                                                  for k, v in history.items()},
                            start=None if start is None else start[p]) for p in range(len(config))]

    @property
    def joints(self) -> Tensor | None:
        """(T, F, j) finger joints of the reported configurations (hand and arm environments)."""
        return self.evaluation.joints

    @property
    def errors(self) -> Tensor | None:
        """(T, F) per-finger errors, metres."""
        return self.evaluation.finger_errors

    @property
    def total(self) -> Tensor:
        """(T,) the evaluation's error, metres (E of eq. 3)."""
        return self.evaluation.error


def run_loop(env: Environment, trials: int, seed: int, solver: SolverCfg | None = None, srv: SRVNetCfg | None = None,
             reward: RewardCfg | None = None, noise: NoiseCfg | None = None, start: Starts | None = None
             ) -> LoopOutcome:
    """Run T trials of the closed loop on one environment (settings default to the paper's).
    ``start``: where the trials start (``solver.start: proposal``): a given start is evaluated as
    the first iteration, and its network's first mean output and expected reinforcement are
    placed there (:meth:`ConfigurationNetwork.place`); None: every trial at random within the
    bounds (the paper)."""
    solver, srv = solver or SolverCfg(), srv or SRVNetCfg()
    noise = noise or NoiseCfg()
    reward_fn = Reward(reward or RewardCfg(), solver.max_iterations, env.reward_base)
    dtype, device = env.lower.dtype, env.lower.device
    T, n = trials, env.n
    gen = torch.Generator(device=device).manual_seed(seed)
    net = ConfigurationNetwork(n, T, srv, gen, dtype=dtype, device=device)
    o_prev = torch.rand(T, n, generator=gen, dtype=dtype, device=device)  # random start within the bounds
    given = None
    if start is not None and bool(start.given.any()):  # given starts: the networks' first mean outputs there
        span = (env.upper - env.lower).clamp_min(torch.finfo(dtype).tiny)
        o_given = ((start.config.to(dtype=dtype, device=device) - env.lower) / span).clamp(START_MARGIN,
                                                                                           1 - START_MARGIN)
        given = start.given.to(device)
        if bool(given.all()):
            o_prev, given = o_given, None  # every trial given: one path
            net.place(o_prev)
        else:
            o_prev = torch.where(given.unsqueeze(1), o_given, o_prev)
            net.place(o_prev, rows=given)
    every = start is not None and bool(start.given.all())  # every trial given (none: all random)
    o_start = o_prev.clone()
    threshold = solver.stop_threshold
    if solver.report not in ("best", "final"):
        raise ValueError(f"solver.report must be 'best' or 'final', got '{solver.report}'")
    curves = Curves()
    with torch.inference_mode(not net.autograd):  # ~30 % less overhead per op; results are cloned out below
        t0 = time.perf_counter()
        best_config, best_ev, best_r, iterations = _iterate(env, net, solver, reward_fn, noise, gen, o_prev,
                                                            threshold, curves, t0, every, given)
        wall = time.perf_counter() - t0
    best_config, best_r, iterations, best_ev = best_config.clone(), best_r.clone(), iterations.clone(), best_ev.clone()
    history = curves.tensors(iterations) if solver.history else None
    if threshold is None:
        success = torch.zeros(T, dtype=torch.bool, device=device)
    elif solver.stop_rule == "grasp" and noise.sigma == 0:
        success = env.grasped(best_ev, solver.tolerance_mm / 1000)
    else:
        success = best_r > threshold
    start = torch.addcmul(env.lower, env.upper - env.lower, o_start)
    return LoopOutcome(config=best_config, evaluation=best_ev, reinforcement=best_r, iterations=iterations,
                       success=success, wall_time_s=wall, history=history, start=start)


@dataclass
class _Search:
    """The loop's state between iterations, one row per trial (R = T; once the loop runs the active trials
    only, R of them): the networks, each trial's best so far, ``o_prev``, ``o_prev2`` (R, n) the last two
    configurations fed back (normalised), ``polished_at`` (R,) the observed reinforcement at each row's
    last polish (-inf: none), ``pending`` (R,) bool the near rows waiting for a polish, the last evaluation."""

    net: ConfigurationNetwork
    best: Tracker
    o_prev: Tensor
    o_prev2: Tensor
    polished_at: Tensor
    pending: Tensor
    ev: Evaluation | None = None


def _iterate(env: Environment, net: ConfigurationNetwork, solver: SolverCfg, reward: Reward, noise: NoiseCfg,
             gen: torch.Generator, o_prev: Tensor, threshold: float | None, curves: Curves,
             t0: float, given: bool = False, some: Tensor | None = None
             ) -> tuple[Tensor, Evaluation, Tensor, Tensor]:
    """The iterations; returns the reported configuration, its evaluation, its (noise-free)
    reinforcement and the iteration count of every trial. With ``given`` starts (every trial's;
    or ``some`` (T,) bool: those trials') the first iteration evaluates the start itself (the
    networks, placed there, learn from the second on).

    Once most trials have stopped (a quarter of the rows still run, 64 rows or more), the loop
    runs on the rows of the trials still active only (:class:`~graspnet_torch.solver.rows.RunningRows`):
    every per-trial tensor below (R, ...) is then theirs, in trial order. The random draws stay every trial's."""
    T, n = o_prev.shape
    dtype, device = o_prev.dtype, o_prev.device
    s = _Search(net=net, best=Tracker(T, reward, solver.max_iterations, env.problem_index, solver.stop, device),
                o_prev=o_prev, o_prev2=o_prev, polished_at=torch.full((T,), -float("inf"), dtype=dtype, device=device),
                pending=torch.zeros(T, dtype=torch.bool, device=device))
    polish_from, first_from = _polish_bars(env, solver, noise, threshold)
    grasp_rule = solver.stop_rule == "grasp" and noise.sigma == 0  # with noise the error is not observed
    tolerance = solver.tolerance_mm / 1000
    part = RunningRows(env, T, env.upper - env.lower)  # the rows the loop runs: all, until most trials have stopped
    for k in range(solver.max_iterations):
        rows = part.rows
        x = torch.cat([s.o_prev, s.o_prev - s.o_prev2], dim=1)
        noise_k = torch.randn(T, n, generator=gen, dtype=dtype, device=device)  # every trial's draw, always
        step = s.net(x, noise_k if rows is None else noise_k[rows])
        o, r_hat, sigma = (s.o_prev if given and k == 0 else step.o), step.r_hat, step.sigma
        if some is not None and k == 0:
            o = torch.where(some.unsqueeze(1), s.o_prev, o)
        s.ev = _evaluate(env, part, s, o, T)
        config = s.ev.config  # the configuration evaluated (where the environment settled the proposal)
        r = reward(s.ev, k + 1)  # (14), (20)-(23)
        observed = part.observe(r, noise.sigma, gen)  # (15)
        _learn(s, observed, (given or some is not None) and k == 0, some)
        s.best.rescore(k + 1)
        s.best.offer(config, s.ev, r, observed, None if solver.report == "best" else torch.ones_like(s.best.active))
        shown = config  # each trial's configuration this iteration (a landed one: where the polish put it)
        if polish_from is not None:  # trials near a solution: the polish lands them (or they learn on)
            observed, r, shown = _polish_step(env, s, reward, solver, k, T, first_from if k == 0 else polish_from,
                                              k == 0 and first_from != polish_from, threshold,
                                              tolerance if grasp_rule else None, rows, observed, r, shown)
        if solver.history:
            _history_row(curves, rows, t0, solver, r, observed, r_hat, sigma, s.ev, shown)
        o_new = o if s.best.all_active else torch.where(s.best.active.unsqueeze(1), o, s.o_prev)
        s.o_prev2, s.o_prev = s.o_prev, o_new
        if solver.time_budget is not None and time.perf_counter() - t0 > solver.time_budget:
            s.best.halt(k + 1)
            break
        if threshold is not None:
            done = _done(env, s, part, solver, gen, observed, threshold, grasp_rule, tolerance)
            if bool(done.any()):
                if not s.best.finish(done, k + 1):
                    break
                _run_rest_only(s, part)
            restart = solver.restart_every is not None and (k + 1) % solver.restart_every == 0
            if restart and k + 1 < solver.max_iterations:
                # still searching: a new network and a new random start (the best so far is kept)
                _restart(s, s.best.active.nonzero().squeeze(1), gen)
    best = part.whole(s.best)
    return best.config, best.evaluation, best.r, best.iterations


def _polish_bars(env: Environment, solver: SolverCfg, noise: NoiseCfg, threshold: float | None
                 ) -> tuple[float | None, float | None]:
    """The observed reinforcement above which a trial is polished inside the loop, and the first
    iteration's: (None, None) when the loop does not polish."""
    polish_from = first_from = None  # solver.polish.from_r (never with sensor noise), from_r_free (the first's)
    if solver.polish.from_r is not None and env.polishes and noise.sigma == 0 and threshold is not None:
        polish_from = first_from = solver.polish.from_r
        if solver.polish.from_r_free is not None and (not env.counts_collisions or env.on_surface):
            first_from = solver.polish.from_r_free
    return polish_from, first_from


def _evaluate(env: Environment, part: RunningRows, s: _Search, o: Tensor, T: int) -> Evaluation:
    """The environment's evaluation of the configurations o (R, n) (normalised; eq. 13): every
    row's, or once most trials have stopped the active ones' only."""
    rows = part.rows
    config = torch.addcmul(part.lower, part.span, o)  # (13)
    if rows is None and (s.best.all_active or s.best.n_active * 2 > T or not env.subsets):
        return env.evaluate(config)  # E of eq. 3 (+ collisions)
    if env.subsets:  # most trials have stopped: evaluate the others only (stopped ones keep a stale row)
        idx = s.best.active.nonzero().squeeze(1)
        return s.ev.put(idx, env.evaluate(config[idx], idx if rows is None else rows[idx]), config)
    return part.evaluate(o)  # evaluated whole: every trial's configuration, the stopped ones' where they stopped


def _learn(s: _Search, observed: Tensor, first: bool, some: Tensor | None) -> None:
    """The networks learn from the observed reinforcement (R,); at a ``first`` iteration that
    evaluated the given starts (every row's, or ``some`` (T,) bool), they are placed there."""
    if first:  # nothing drawn to learn from; the networks expect what the start got (narrow exploration near
        # a grasp), but for a colliding start (R3/R4 weigh its collisions more with every iteration): wide
        clear = None if s.ev.collisions is None else s.ev.collisions.to(s.o_prev.device) == 0
        if some is not None:
            s.net.reinforce(observed, ~some)  # the others learn from their first draw
        clear_rows = some if clear is None else clear if some is None else some & clear
        s.net.place(s.o_prev, observed, rows=clear_rows)
    else:
        s.net.reinforce(observed, None if s.best.all_active else s.best.active)  # (16)-(19)


def _polish_step(env: Environment, s: _Search, reward: Reward, solver: SolverCfg, k: int, T: int, bar: float,
                 landed_only: bool, threshold: float, tolerance: float | None, rows: Tensor | None, observed: Tensor,
                 r: Tensor, shown: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Polish the active rows observed above ``bar`` and their last polish's at iteration ``k`` (a large
    batch: a few wait for others); returns the observed and noise-free reinforcements (R,) and shown
    configurations (R, n), and sets ``s.ev``, with the landed rows' where the polish put them."""
    near = s.best.active & (observed > bar) & (observed > s.polished_at)
    s.polished_at = torch.where(near, observed, s.polished_at)
    if T >= DEFER_FROM:  # a large batch: a few near trials wait for others (or a few iterations)
        s.pending = (s.pending | near) & s.best.active
        near = s.pending if int(s.pending.sum()) >= DEFER_ROWS or (k + 1) % DEFER_EVERY == 0 else near & False
    if not bool(near.any()):
        return observed, r, shown
    s.pending = s.pending & ~near
    landed = _polish_near(env, near, s.best, reward, k + 1, threshold, solver, tolerance, landed_only=landed_only,
                          rows=rows)
    observed = torch.where(landed, s.best.observed, observed)  # the stop below sees the landed ones
    r = torch.where(landed, s.best.r, r)  # a landed trial is where the polish put it: its curves
    s.ev = s.best.evaluation.where(landed, s.ev)  # end there, and its collision count is the landed one's
    if solver.history_postures:
        shown = torch.where(landed.unsqueeze(1), s.best.config, shown)
    return observed, r, shown


def _history_row(curves: Curves, rows: Tensor | None, t0: float, solver: SolverCfg, r: Tensor, observed: Tensor,
                 r_hat: Tensor, sigma: Tensor, ev: Evaluation, shown: Tensor) -> None:
    """Add one iteration's row to the curves (``solver.history_postures``: the shown postures too)."""
    values = {"reinforcement": r, "observed": observed, "expected": r_hat, "sigma": sigma, "total": ev.error,
              "errors": ev.finger_errors, "collisions": ev.collisions, "alignment": ev.alignment}
    if solver.history_postures:  # each trial's configuration and finger joints: the viewer's replay
        values["config"] = shown.clone()
        values["joints"] = None if ev.joints is None else ev.joints.clone()
    curves.add(rows, time.perf_counter() - t0, values)


def _done(env: Environment, s: _Search, part: RunningRows, solver: SolverCfg, gen: torch.Generator,
          observed: Tensor, threshold: float, grasp_rule: bool, tolerance: float) -> Tensor:
    """(R,) bool: the active rows that meet the stopping rule: ``grasp_rule``, a grasp in the model
    within ``tolerance`` (m), clear by the exact check too (a refused row starts again); else the
    observed reinforcement (R,) exceeds the threshold."""
    if grasp_rule:  # the configuration is a grasp in the model (within the tolerance, clear)
        done = s.best.active & env.grasped(s.ev, tolerance)
        if env.counts_collisions and bool(done.any()):  # ... and clear by the exact check (the proxy can miss a link)
            idx = done.nonzero().squeeze(1)
            refused = torch.zeros_like(done).index_fill(0, idx[~part.confirm(s.best, idx).to(s.o_prev.device)], True)
            if bool(refused.any()):  # those trials start again: new network, new random start
                done = done & ~refused
                s.best.forget(refused)
                _restart(s, refused.nonzero().squeeze(1), gen)
    else:  # the paper's rule: the observed reinforcement exceeds the threshold
        done = s.best.active & (observed > threshold)
        if solver.stops_clear and s.ev.collisions is not None:  # a colliding grasp is no reason to stop
            done &= s.ev.collisions == 0
    return done


def _restart(s: _Search, idx: Tensor, gen: torch.Generator) -> None:
    """The rows ``idx`` start again: a new network, a new random start (their best so far is kept)."""
    s.net.restart(idx, gen)
    s.o_prev = s.o_prev.index_copy(0, idx, torch.rand(idx.numel(), s.o_prev.shape[1], generator=gen,
                                                      dtype=s.o_prev.dtype, device=s.o_prev.device))
    s.o_prev2 = s.o_prev
    s.polished_at = s.polished_at.index_fill(0, idx, -float("inf"))


def _run_rest_only(s: _Search, part: RunningRows) -> None:
    """With a quarter or fewer of 64 or more rows active, every row of ``s`` taken to the active ones."""
    running = s.o_prev.shape[0]
    if s.best.n_active * 4 <= running and running >= 64 and not s.net.autograd:  # run the rest only
        keep = s.best.active.nonzero().squeeze(1)
        s.net = s.net.select(keep)
        s.best = part.select(keep, s.best, s.o_prev)
        s.o_prev, s.o_prev2, s.ev = s.o_prev[keep], s.o_prev2[keep], take_rows(s.ev, keep)
        s.polished_at, s.pending = s.polished_at[keep], s.pending[keep]


def _polish_near(env: Environment, near: Tensor, best: Tracker, reward: Reward, iteration: int, threshold: float,
                 solver: SolverCfg, tolerance: float | None = None, landed_only: bool = False,
                 rows: Tensor | None = None) -> Tensor:
    """Polish the best configurations of the rows ``near`` (R,) (the trials ``rows`` (R,); None:
    every trial, R = T) (the environment's
    :meth:`~graspnet_torch.solver.environment.Environment.polish`) and keep each where it is
    better (``landed_only``: and has landed with its summed error within ``tolerance`` too, so that
    a trial's best never becomes a local minimum the polish found far from a solution, which later
    polishes would start from again); returns (R,) which polished rows have now landed: are a
    grasp within ``tolerance`` (metres; None: exceed the threshold)."""
    config, ev, r = best.config, best.evaluation, best.r
    idx = near.nonzero().squeeze(1)
    trials = idx if rows is None else rows[idx]
    part = Evaluation(**{k: v[idx] for k, v in ev.tensors().items()})
    done = None
    if solver.stop is not None:  # the polish ends once enough of a problem's trials have landed
        pid = None if env.problem_index is None else env.problem_index[trials].cpu()

        def done(converged: Tensor) -> Tensor:
            return enough_succeeded(converged, pid, solver.stop)
    new_config, new_ev = env.polish(config[idx], part, trials, done)
    new_r = reward(new_ev, iteration)
    better = new_r > r[idx]
    if landed_only:  # landed, and (grasp rule) with the summed error within tolerance too: not a near miss
        # (the surface model: every pad within tolerance, facing within the cone, is the grasp itself)
        better &= new_r > threshold if tolerance is None else env.grasped(new_ev, tolerance) & (
            env.on_surface or new_ev.error.to(new_r.device) <= tolerance)
    take = torch.zeros_like(near).index_fill(0, idx[better], True)
    best.config = config.index_copy(0, idx, torch.where(better.unsqueeze(1), new_config, config[idx]))
    best.evaluation = ev.put(idx, new_ev.where(better, part), best.config)
    best.r = r.index_copy(0, idx, torch.where(better, new_r, r[idx]))
    best.observed = torch.where(take, best.r, best.observed)
    landed = best.r > threshold if tolerance is None else env.grasped(best.evaluation, tolerance)
    return take & landed


