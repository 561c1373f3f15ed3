"""``solver=cmaes``: CMA-ES over the same configuration, with the same reinforcement, as a black box.

One independent CMA-ES (Hansen's evolution strategy, the ``cmaes`` package) per trial searches the
normalised configuration space [0, 1]^n that the configuration network's output o lives in
(eq. 13), from a random start (the same draw as the SRV loop's with the same seed), with step size
``solver.step_size``. Each generation, the populations of every active trial are evaluated as one
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
from graspnet_torch.solver.loop import LoopOutcome, enough_succeeded

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
    reward_fn = Reward(reward or RewardCfg(), solver.max_iterations)
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
    pop = solver.population or 4 + int(3 * math.log(n))

    def make(t: int, mean: np.ndarray, k: int) -> CMA:
        return CMA(mean=mean, sigma=solver.step_size, bounds=box, seed=(seed * 1_000_003 + t * 7919 + k) % 2**31,
                   population_size=pop)

    opts = [make(t, o0[t].double().cpu().numpy(), 0) for t in range(T)]
    restarts = [0] * T
    budget, threshold = solver.max_iterations, solver.stop_threshold
    problem_index = getattr(env, "problem_index", None)
    active = torch.ones(T, dtype=torch.bool)
    succeeded = torch.zeros(T, dtype=torch.bool)
    iterations = torch.full((T,), budget, dtype=torch.long)
    best_obs = torch.full((T,), -math.inf, dtype=torch.float64)
    best_r = torch.full((T,), -math.inf, dtype=torch.float64)
    best_o = o0.double().cpu().clone()
    best_ev: Evaluation | None = None
    hist: dict[str, list] = {}
    used = 0
    t0 = time.perf_counter()
    with torch.inference_mode():
        while used < budget and bool(active.any()):
            idx = active.nonzero().squeeze(1)
            A, k = idx.numel(), min(pop, budget - used)
            asked = [[opts[int(t)].ask() for _ in range(pop)] for t in idx]
            o = torch.as_tensor(np.asarray(asked)[:, :k], dtype=dtype, device=device)  # (A, k, n)
            rows = idx.repeat_interleave(k).to(device)
            lo = lower[rows] if lower.dim() == 2 else lower
            config = torch.addcmul(lo, (upper[rows] if upper.dim() == 2 else upper) - lo, o.reshape(A * k, n))
            ev = env.evaluate(config, rows if problem_index is not None else None)
            if ev.config is not None:  # the environment settled the proposals (a gripper's refine steps)
                config = ev.config
                o = ((config - lo) / ((upper[rows] if upper.dim() == 2 else upper) - lo)).reshape(A, k, n)
            i = used + torch.arange(1, k + 1, device=device).repeat(A)
            r = reward_fn(ev, i).double().cpu()
            observed = add_noise(r.to(dtype), noise.sigma, gen).double().cpu() if noise.sigma > 0 else r
            obs_ak, r_ak = observed.view(A, k), r.view(A, k)
            j = obs_ak.argmax(dim=1)  # each trial's best candidate of this generation
            pick = torch.arange(A) * k + j
            gen_obs, gen_r = obs_ak[torch.arange(A), j], r_ak[torch.arange(A), j]
            if best_ev is not None and best_ev.collisions is not None and reward_fn.cfg.kind in ("r3", "r4"):
                # shaping grows with i (eq. 22-23): the kept candidate is scored as it would be now
                rescored = reward_fn(best_ev, torch.full((T,), used + k, device=device)).double().cpu()
                best_obs, best_r = best_obs + (rescored - best_r), rescored
            better = gen_obs > best_obs[idx]
            part = Evaluation(**{name: v[pick] for name, v in ev.tensors().items() if name != "config"})
            if best_ev is None:  # the first generation evaluates every trial
                best_ev = part.clone()
            else:
                take = idx[better]
                best_ev = _assign(best_ev, take.to(device), part, better.to(device))
            best_obs[idx] = torch.where(better, gen_obs, best_obs[idx])
            best_r[idx] = torch.where(better, gen_r, best_r[idx])
            best_o[idx] = torch.where(better.unsqueeze(1), o[torch.arange(A), j].double().cpu(), best_o[idx])
            if solver.history:
                row = {"reinforcement": best_r.clone(), "observed": best_obs.clone(),
                       "total": best_ev.error.double().cpu().clone(),
                       "step_size": torch.tensor([float(getattr(opt, "_sigma", float("nan"))) for opt in opts])}
                if best_ev.finger_errors is not None:
                    row["errors"] = best_ev.finger_errors.double().cpu().clone()
                if best_ev.collisions is not None:
                    row["collisions"] = best_ev.collisions.double().cpu().clone()
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
                        opts[t] = make(t, best_o[t].numpy().clip(0, 1), restarts[t])
            if threshold is not None:
                hit = obs_ak > threshold
                done = torch.zeros(T, dtype=torch.bool)
                done[idx] = hit.any(dim=1)
                first = used + hit.float().argmax(dim=1) + 1
                iterations[idx] = torch.where(hit.any(dim=1), first, iterations[idx])
                succeeded |= done
                if solver.stop is not None:
                    more = active & ~done & enough_succeeded(succeeded, problem_index, solver.stop)
                    iterations = torch.where(more, torch.full_like(iterations, used + k), iterations)
                    done |= more
                active &= ~done
            if solver.time_budget is not None and time.perf_counter() - t0 > solver.time_budget:
                iterations = torch.where(active, torch.full_like(iterations, used + k), iterations)
                break
            used += k
    wall = time.perf_counter() - t0
    config = torch.addcmul(lower, span, best_o.to(dtype=dtype, device=device))
    history = None
    if solver.history and hist:
        history = {key: torch.stack(v) for key, v in hist.items() if key not in ("time", "iteration")}
        history["time"] = torch.tensor(hist["time"], dtype=torch.float64)
        history["iteration"] = torch.tensor(hist["iteration"], dtype=torch.long)
    threshold_ok = best_obs > threshold if threshold is not None else torch.zeros(T, dtype=torch.bool)
    return LoopOutcome(config=config, evaluation=best_ev, reinforcement=best_r.to(dtype=dtype, device=device),
                       iterations=iterations.to(device), success=threshold_ok.to(device), wall_time_s=wall,
                       history=history, start=torch.addcmul(lower, span, o0))


def _assign(best: Evaluation, trials: Tensor, part: Evaluation, better: Tensor) -> Evaluation:
    """``best`` with rows ``trials`` replaced by the rows of ``part`` where ``better``."""
    out = {}
    for name, mine in best.tensors().items():
        out[name] = mine.index_copy(0, trials, getattr(part, name)[better])
    return Evaluation(**out)
