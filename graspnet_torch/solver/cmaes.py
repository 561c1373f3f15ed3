"""``solver=cmaes``: CMA-ES over the same configuration, with the same reinforcement, as a black box.

One independent CMA-ES (Hansen's evolution strategy, the ``cmaes`` package) per trial searches the
normalised configuration space [0, 1]^n that the configuration network's output o lives in
(eq. 13), from a random start (the same draw as the SRV loop's with the same seed), with step size
``solver.cmaes.step_size``. Each generation, the populations of every active trial are evaluated as one
batch by the environment; each candidate's reinforcement is the ``reward`` group's (R1-R4, with i
the trial's evaluations so far and p the budget), plus the sensor noise N(0, sigma_n) (eq. 15): it
sees exactly what the SRV loop sees. One evaluation is one iteration, so ``max_iterations`` is a
budget of observations. A trial stops once an observed reinforcement exceeds the threshold (a
problem once ``solver.stop`` trials have), and reports its candidate with the highest observed
reinforcement, as the loop does. A converged CMA-ES restarts around its best with the initial
step size.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.rewards import Reward, add_noise
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.environment import Environment, Evaluation
from graspnet_torch.solver.loop import LoopOutcome
from graspnet_torch.solver.tracker import Tracker

if TYPE_CHECKING:  # pragma: no cover
    from cmaes import CMA

__all__ = ["run_cmaes"]


def run_cmaes(env: Environment, trials: int, seed: int, solver: SolverCfg | None = None,
              reward: RewardCfg | None = None, noise: NoiseCfg | None = None, start: Tensor | None = None
              ) -> LoopOutcome:
    """T independent CMA-ES runs on one environment (a batch of problems: ``env.problem_index``).

    Args:
        start: (T, n) starts in the environment's units; None: uniform within the bounds, the
            SRV loop's draw for the same seed.

    Returns:
        a :class:`LoopOutcome`; its history has one row per generation (each trial's best so far:
        reinforcement, observed reinforcement, error; the CMA-ES step size under 'step_size';
        'iteration': evaluations used).
    """
    from cmaes import CMA

    solver = solver or SolverCfg(method="cmaes")
    noise = noise or NoiseCfg()
    reward_fn = Reward(reward or RewardCfg(), solver.max_iterations, env.reward_base)
    lower, upper = env.lower, env.upper
    dtype, device = lower.dtype, lower.device
    T, n = trials, env.n
    span = upper - lower
    gen = torch.Generator(device=device).manual_seed(seed)
    if start is None:
        o0 = torch.rand(T, n, generator=gen, dtype=dtype, device=device)  # the SRV loop's first draw
    else:
        o0 = ((start.to(lower) - lower) / span).clamp(0, 1)
    box = np.stack([np.zeros(n), np.ones(n)], axis=1)
    pop = solver.cmaes.population or 4 + int(3 * math.log(n))

    def make(t: int, mean: np.ndarray, k: int) -> CMA:
        return CMA(mean=mean, sigma=solver.cmaes.step_size, bounds=box, seed=(seed * 1_000_003 + t * 7919 + k) % 2**31,
                   population_size=pop)

    opts = [make(t, o0[t].double().cpu().numpy(), 0) for t in range(T)]
    restarts = [0] * T
    budget, threshold = solver.max_iterations, solver.stop_threshold
    pid = None if env.problem_index is None else env.problem_index.cpu()
    best = Tracker(T, reward_fn, budget, pid, solver.stop)  # kept in the normalised units o, float64 on the CPU
    best.start(o0.double().cpu())
    hist: dict[str, list] = {}
    used = 0
    t0 = time.perf_counter()
    with torch.inference_mode():
        while used < budget and bool(best.active.any()):
            idx = best.active.nonzero().squeeze(1)
            k = min(pop, budget - used)
            asked = [[opts[int(t)].ask() for _ in range(pop)] for t in idx]
            o, ev, obs_ak, r_ak = _generation(env, reward_fn, noise, gen, asked, idx, k, used)
            _offer_generation(best, idx, o, ev, obs_ak, r_ak, used + k)
            if solver.history:
                _trace_row(hist, best, opts, t0, used + k)
            if k == pop:
                _tell(opts, make, restarts, best, idx, asked, obs_ak)
            if threshold is not None:
                _finish_hits(best, idx, obs_ak, threshold, used, k)
            if solver.time_budget is not None and time.perf_counter() - t0 > solver.time_budget:
                best.halt(used + k)
                break
            used += k
    wall = time.perf_counter() - t0
    config = torch.addcmul(lower, span, best.config.to(dtype=dtype, device=device))
    history = _history_tensors(hist) if solver.history and hist else None
    threshold_ok = best.observed > threshold if threshold is not None else torch.zeros(T, dtype=torch.bool)
    return LoopOutcome(config=config, evaluation=best.evaluation, reinforcement=best.r.to(dtype=dtype, device=device),
                       iterations=best.iterations.to(device), success=threshold_ok.to(device), wall_time_s=wall,
                       history=history, start=torch.addcmul(lower, span, o0))


def _generation(env: Environment, reward_fn: Reward, noise: NoiseCfg, gen: torch.Generator, asked: list[list],
                idx: Tensor, k: int, used: int) -> tuple[Tensor, Evaluation, Tensor, Tensor]:
    """Evaluate the first ``k`` candidates that the A active trials ``idx`` (A,) were asked for, as
    one batch: returns the candidates o (A, k, n) (normalised; where the environment settled them),
    the evaluation (A k rows), and the observed and noise-free reinforcements (A, k) (float64, CPU;
    candidate c of a generation is evaluation ``used + c + 1`` of its trial)."""
    lower, upper = env.lower, env.upper
    dtype, device = lower.dtype, lower.device
    A, n = idx.numel(), env.n
    o = torch.as_tensor(np.asarray(asked)[:, :k], dtype=dtype, device=device)  # (A, k, n)
    rows = idx.repeat_interleave(k).to(device)
    lo = lower[rows] if lower.dim() == 2 else lower
    config = torch.addcmul(lo, (upper[rows] if upper.dim() == 2 else upper) - lo, o.reshape(A * k, n))
    ev = env.evaluate(config, rows if env.problem_index is not None else None)
    if ev.config is not config:  # the environment settled the proposals: search from where they went
        o = ((ev.config - lo) / ((upper[rows] if upper.dim() == 2 else upper) - lo)).reshape(A, k, n)
    i = used + torch.arange(1, k + 1, device=device).repeat(A)
    r = reward_fn(ev, i).double().cpu()
    observed = add_noise(r.to(dtype), noise.sigma, gen).double().cpu() if noise.sigma > 0 else r
    return o, ev, observed.view(A, k), r.view(A, k)


def _offer_generation(best: Tracker, idx: Tensor, o: Tensor, ev: Evaluation, obs_ak: Tensor, r_ak: Tensor,
                      at: int) -> None:
    """Offer each active trial's (``idx`` (A,)) best candidate of the generation (its highest
    observed reinforcement in ``obs_ak`` (A, k)) to the tracker, rescored at evaluation ``at``."""
    A, k = obs_ak.shape
    j = obs_ak.argmax(dim=1)  # each trial's best candidate of this generation
    pick = torch.arange(A) * k + j
    gen_obs, gen_r = obs_ak[torch.arange(A), j], r_ak[torch.arange(A), j]
    best.rescore(torch.full((best.active.shape[0],), at, device=o.device))
    part = Evaluation(**{name: v[pick] for name, v in ev.tensors().items() if name != "config"})
    best.offer_rows(idx, o[torch.arange(A), j].double().cpu(), part, gen_r, gen_obs)


def _trace_row(hist: dict[str, list], best: Tracker, opts: list[CMA], t0: float, at: int) -> None:
    """Append one generation's row to the history lists: each trial's best so far (reinforcement,
    observed, error (m), finger errors and collisions where given), each CMA-ES's step size, the
    seconds since ``t0`` and the evaluations used ``at``."""
    row = {"reinforcement": best.r.clone(), "observed": best.observed.clone(),
           "total": best.evaluation.error.double().cpu().clone(),
           "step_size": torch.tensor([float(getattr(opt, "_sigma", float("nan"))) for opt in opts])}
    if best.evaluation.finger_errors is not None:
        row["errors"] = best.evaluation.finger_errors.double().cpu().clone()
    if best.evaluation.collisions is not None:
        row["collisions"] = best.evaluation.collisions.double().cpu().clone()
    for key, value in row.items():
        hist.setdefault(key, []).append(value)
    hist.setdefault("time", []).append(time.perf_counter() - t0)
    hist.setdefault("iteration", []).append(at)


def _tell(opts: list[CMA], make: Callable[[int, np.ndarray, int], CMA], restarts: list[int], best: Tracker,
          idx: Tensor, asked: list[list], obs_ak: Tensor) -> None:
    """Tell each active trial's CMA-ES (``idx`` (A,)) its whole generation (``asked``, scored by
    minus the observed reinforcement ``obs_ak`` (A, pop)); a converged one restarts around its
    trial's best with the initial step size."""
    pop = obs_ak.shape[1]
    obs_np = obs_ak.numpy()
    for a, t in enumerate(idx.tolist()):
        opts[t].tell([(asked[a][c], -float(obs_np[a, c])) for c in range(pop)])
        if opts[t].should_stop():  # converged: restart around its best with the initial step size
            restarts[t] += 1
            opts[t] = make(t, best.config[t].numpy().clip(0, 1), restarts[t])


def _finish_hits(best: Tracker, idx: Tensor, obs_ak: Tensor, threshold: float, used: int, k: int) -> None:
    """Stop the active trials (``idx`` (A,)) whose observed reinforcement (A, k) exceeded the
    threshold this generation, each at its first such evaluation."""
    T = best.active.shape[0]
    hit = obs_ak > threshold
    done = torch.zeros(T, dtype=torch.bool)
    done[idx] = hit.any(dim=1)
    at = torch.full((T,), used + k, dtype=torch.long)  # a trial that hit: its first hit
    at[idx] = torch.where(hit.any(dim=1), used + hit.float().argmax(dim=1) + 1, at[idx])
    if bool(done.any()):
        best.finish(done, at)


def _history_tensors(hist: dict[str, list]) -> dict[str, Tensor]:
    """The history lists stacked: (G, T) per generation and trial; 'time' (G,) seconds, 'iteration' (G,)."""
    history = {key: torch.stack(v) for key, v in hist.items() if key not in ("time", "iteration")}
    history["time"] = torch.tensor(hist["time"], dtype=torch.float64)
    history["iteration"] = torch.tensor(hist["iteration"], dtype=torch.long)
    return history
