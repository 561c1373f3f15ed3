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
    span = env.upper - env.lower
    o_prev2 = o_prev
    best = Tracker(T, reward, solver.max_iterations, env.problem_index, solver.stop, device)
    polish_from = None  # the polish inside the loop (solver.polish.from_r; never with sensor noise)
    first_from = None  # the first iteration's (solver.polish.from_r_free: nothing to collide with)
    if solver.polish.from_r is not None and env.polishes and noise.sigma == 0 and threshold is not None:
        polish_from = first_from = solver.polish.from_r
        if solver.polish.from_r_free is not None and (not env.counts_collisions or env.on_surface):
            first_from = solver.polish.from_r_free
    polished_at = torch.full((T,), -float("inf"), dtype=dtype, device=device)
    pending = torch.zeros(T, dtype=torch.bool, device=device)
    grasp_rule = solver.stop_rule == "grasp" and noise.sigma == 0  # with noise the error is not observed
    confirm = grasp_rule and env.counts_collisions  # a grasp stops a trial once FCL, too, finds it clear
    tolerance = solver.tolerance_mm / 1000
    part = RunningRows(env, T, span)  # the rows the loop runs: all, until most trials have stopped
    ev = None
    for k in range(solver.max_iterations):
        rows = part.rows
        x = torch.cat([o_prev, o_prev - o_prev2], dim=1)
        noise_k = torch.randn(T, n, generator=gen, dtype=dtype, device=device)  # every trial's draw, always
        step = net(x, noise_k if rows is None else noise_k[rows])
        o, r_hat, sigma = (o_prev if given and k == 0 else step.o), step.r_hat, step.sigma
        if some is not None and k == 0:
            o = torch.where(some.unsqueeze(1), o_prev, o)
        config = torch.addcmul(part.lower, part.span, o)  # (13)
        if rows is None and (best.all_active or best.n_active * 2 > T or not env.subsets):
            ev = env.evaluate(config)  # E of eq. 3 (+ collisions)
        elif env.subsets:  # most trials have stopped: evaluate the others only (stopped ones keep a stale row)
            idx = best.active.nonzero().squeeze(1)
            ev = ev.put(idx, env.evaluate(config[idx], idx if rows is None else rows[idx]), config)
        else:  # an environment evaluated whole: every trial's configuration, the stopped ones' where they stopped
            ev = part.evaluate(o)
        config = ev.config  # the configuration evaluated (where the environment settled the proposal)
        r = reward(ev, k + 1)  # (14), (20)-(23)
        observed = part.observe(r, noise.sigma, gen)  # (15)
        if (given or some is not None) and k == 0:  # the start itself was evaluated: nothing drawn to learn
            # from; the networks expect what the start got (narrow exploration near a grasp), but for
            # a colliding start (R3/R4 weigh its collisions more with every iteration): wide
            clear = None if ev.collisions is None else ev.collisions.to(device) == 0
            if some is not None:
                net.reinforce(observed, ~some)  # the others learn from their first draw
            clear_rows = some if clear is None else clear if some is None else some & clear
            net.place(o_prev, observed, rows=clear_rows)
        else:
            net.reinforce(observed, None if best.all_active else best.active)  # (16)-(19)
        best.rescore(k + 1)
        best.offer(config, ev, r, observed, None if solver.report == "best" else torch.ones_like(best.active))
        shown = config  # each trial's configuration this iteration (a landed one: where the polish put it)
        if polish_from is not None:  # trials near a solution: the polish lands them (or they learn on)
            near = best.active & (observed > (first_from if k == 0 else polish_from)) & (observed > polished_at)
            polished_at = torch.where(near, observed, polished_at)
            if T >= DEFER_FROM:  # a large batch: a few near trials wait for others (or a few iterations)
                pending = (pending | near) & best.active
                near = pending if int(pending.sum()) >= DEFER_ROWS or (k + 1) % DEFER_EVERY == 0 else near & False
            if bool(near.any()):
                pending = pending & ~near
                landed = _polish_near(env, near, best, reward, k + 1, threshold, solver,
                                      tolerance if grasp_rule else None,
                                      landed_only=k == 0 and first_from != polish_from, rows=rows)
                observed = torch.where(landed, best.observed, observed)  # the stop below sees the landed ones
                r = torch.where(landed, best.r, r)  # a landed trial is where the polish put it: its curves
                ev = best.evaluation.where(landed, ev)  # end there, and its collision count is the landed one's
                if solver.history_postures:
                    shown = torch.where(landed.unsqueeze(1), best.config, shown)
        if solver.history:
            values = {"reinforcement": r, "observed": observed, "expected": r_hat, "sigma": sigma, "total": ev.error,
                      "errors": ev.finger_errors, "collisions": ev.collisions, "alignment": ev.alignment}
            if solver.history_postures:  # each trial's configuration and finger joints: the viewer's replay
                values["config"] = shown.clone()
                values["joints"] = None if ev.joints is None else ev.joints.clone()
            curves.add(rows, time.perf_counter() - t0, values)
        o_new = o if best.all_active else torch.where(best.active.unsqueeze(1), o, o_prev)
        o_prev2, o_prev = o_prev, o_new
        if solver.time_budget is not None and time.perf_counter() - t0 > solver.time_budget:
            best.halt(k + 1)
            break
        if threshold is not None:
            if grasp_rule:  # the configuration is a grasp in the model (within the tolerance, clear)
                done = best.active & env.grasped(ev, tolerance)
                if confirm and bool(done.any()):  # ... and clear by the exact check (the proxy can miss a link)
                    idx = done.nonzero().squeeze(1)
                    refused = torch.zeros_like(done).index_fill(0, idx[~part.confirm(best, idx).to(device)], True)
                    if bool(refused.any()):  # those trials start again: new network, new random start
                        done = done & ~refused
                        best.forget(refused)
                        idx = refused.nonzero().squeeze(1)
                        net.restart(idx, gen)
                        o_prev = o_prev.index_copy(0, idx, torch.rand(idx.numel(), n, generator=gen, dtype=dtype,
                                                                      device=device))
                        o_prev2 = o_prev
                        polished_at = polished_at.index_fill(0, idx, -float("inf"))
            else:  # the paper's rule: the observed reinforcement exceeds the threshold
                done = best.active & (observed > threshold)
                if solver.stops_clear and ev.collisions is not None:  # a colliding grasp is no reason to stop
                    done &= ev.collisions == 0
            if bool(done.any()):
                if not best.finish(done, k + 1):
                    break
                running = o_prev.shape[0]
                if best.n_active * 4 <= running and running >= 64 and not net.autograd:  # run the rest only
                    keep = best.active.nonzero().squeeze(1)
                    net = net.select(keep)
                    best = part.select(keep, best, o_prev)
                    o_prev, o_prev2, ev = o_prev[keep], o_prev2[keep], take_rows(ev, keep)
                    polished_at, pending = polished_at[keep], pending[keep]
            restart = solver.restart_every is not None and (k + 1) % solver.restart_every == 0
            if restart and k + 1 < solver.max_iterations:
                # still searching: a new network and a new random start (the best so far is kept)
                idx = best.active.nonzero().squeeze(1)
                net.restart(idx, gen)
                o_prev = o_prev.index_copy(0, idx, torch.rand(idx.numel(), n, generator=gen, dtype=dtype,
                                                              device=device))
                o_prev2 = o_prev
                polished_at = polished_at.index_fill(0, idx, -float("inf"))
    best = part.whole(best)
    return best.config, best.evaluation, best.r, best.iterations


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


