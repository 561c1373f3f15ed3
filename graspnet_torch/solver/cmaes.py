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

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.rewards import Reward, add_noise
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.environment import Environment, Evaluation
from graspnet_torch.solver.loop import LoopOutcome
from graspnet_torch.solver.tracker import Tracker

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
    problem_index = env.problem_index
    pid = None if problem_index is None else problem_index.cpu()
    best = Tracker(T, reward_fn, budget, pid, solver.stop)  # kept in the normalised units o, float64 on the CPU
    best.start(o0.double().cpu())
    hist: dict[str, list] = {}
    used = 0
    t0 = time.perf_counter()
    with torch.inference_mode():
        while used < budget and bool(best.active.any()):
            idx = best.active.nonzero().squeeze(1)
            A, k = idx.numel(), min(pop, budget - used)
            asked = [[opts[int(t)].ask() for _ in range(pop)] for t in idx]
            o = torch.as_tensor(np.asarray(asked)[:, :k], dtype=dtype, device=device)  # (A, k, n)
            rows = idx.repeat_interleave(k).to(device)
            lo = lower[rows] if lower.dim() == 2 else lower
            config = torch.addcmul(lo, (upper[rows] if upper.dim() == 2 else upper) - lo, o.reshape(A * k, n))
            ev = env.evaluate(config, rows if problem_index is not None else None)
            if ev.config is not config:  # the environment settled the proposals: search from where they went
                o = ((ev.config - lo) / ((upper[rows] if upper.dim() == 2 else upper) - lo)).reshape(A, k, n)
            i = used + torch.arange(1, k + 1, device=device).repeat(A)
            r = reward_fn(ev, i).double().cpu()
            observed = add_noise(r.to(dtype), noise.sigma, gen).double().cpu() if noise.sigma > 0 else r
            obs_ak, r_ak = observed.view(A, k), r.view(A, k)
            j = obs_ak.argmax(dim=1)  # each trial's best candidate of this generation
            pick = torch.arange(A) * k + j
            gen_obs, gen_r = obs_ak[torch.arange(A), j], r_ak[torch.arange(A), j]
            best.rescore(torch.full((T,), used + k, device=device))
            part = Evaluation(**{name: v[pick] for name, v in ev.tensors().items() if name != "config"})
            best.offer_rows(idx, o[torch.arange(A), j].double().cpu(), part, gen_r, gen_obs)
            if solver.history:
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
                hist.setdefault("iteration", []).append(used + k)
            if k == pop:
                obs_np = obs_ak.numpy()
                for a, t in enumerate(idx.tolist()):
                    opts[t].tell([(asked[a][c], -float(obs_np[a, c])) for c in range(pop)])
                    if opts[t].should_stop():  # converged: restart around its best with the initial step size
                        restarts[t] += 1
                        opts[t] = make(t, best.config[t].numpy().clip(0, 1), restarts[t])
            if threshold is not None:
                hit = obs_ak > threshold
                done = torch.zeros(T, dtype=torch.bool)
                done[idx] = hit.any(dim=1)
                at = torch.full((T,), used + k, dtype=torch.long)  # a trial that hit: its first hit
                at[idx] = torch.where(hit.any(dim=1), used + hit.float().argmax(dim=1) + 1, at[idx])
                if bool(done.any()):
                    best.finish(done, at)
            if solver.time_budget is not None and time.perf_counter() - t0 > solver.time_budget:
                best.halt(used + k)
                break
            used += k
    wall = time.perf_counter() - t0
    config = torch.addcmul(lower, span, best.config.to(dtype=dtype, device=device))
    history = None
    if solver.history and hist:
        history = {key: torch.stack(v) for key, v in hist.items() if key not in ("time", "iteration")}
        history["time"] = torch.tensor(hist["time"], dtype=torch.float64)
        history["iteration"] = torch.tensor(hist["iteration"], dtype=torch.long)
    threshold_ok = best.observed > threshold if threshold is not None else torch.zeros(T, dtype=torch.bool)
    return LoopOutcome(config=config, evaluation=best.evaluation, reinforcement=best.r.to(dtype=dtype, device=device),
                       iterations=best.iterations.to(device), success=threshold_ok.to(device), wall_time_s=wall,
                       history=history, start=torch.addcmul(lower, span, o0))

