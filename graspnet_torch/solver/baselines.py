"""Baselines beside the SRV loop on the same environment and reward: CMA-ES as a black box.

CMA-ES (Hansen's evolution strategy, the ``cmaes`` package) searches the same normalised
configuration space [0, 1]^n as the configuration network (eq. 13), from the same start, and
sees the same signal: the reward of the ``reward`` group (R1-R4) of the environment's evaluation,
with i the number of evaluations so far (one evaluation = one SRV iteration) and p the budget.
It stops once an evaluation's reinforcement exceeds the threshold, as the loop does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.rewards import Reward
from graspnet_torch.solver.config import RewardCfg
from graspnet_torch.solver.environment import Environment, Evaluation

__all__ = ["CMAESOutcome", "cmaes_search"]


@dataclass
class CMAESOutcome:
    """The best configuration CMA-ES evaluated.

    Attributes:
        config: (n,) configuration (the environment's units).
        evaluation: its evaluation (leading dimension 1).
        reinforcement: its reinforcement when it was evaluated.
        evaluations: evaluations used (its stop or the budget).
        success: reinforcement exceeded the threshold.
    """

    config: Tensor
    evaluation: Evaluation
    reinforcement: float
    evaluations: int
    success: bool


def cmaes_search(env: Environment, start: Tensor, reward: RewardCfg, budget: int = 2000, threshold: float = 0.99,
                 sigma: float = 0.25, seed: int = 0) -> CMAESOutcome:
    """CMA-ES over the environment's configuration, normalised to [0, 1]^n, from ``start`` (n,)
    (environment units) with step size ``sigma`` (normalised); at most ``budget`` evaluations."""
    from cmaes import CMA

    lower, upper = env.lower, env.upper
    span = upper - lower
    x0 = ((start.to(lower) - lower) / span).clamp(0, 1).double().cpu().numpy()
    n = x0.size
    opt = CMA(mean=x0, sigma=sigma, bounds=np.stack([np.zeros(n), np.ones(n)], axis=1), seed=seed)
    reward_fn = Reward(reward, budget)
    used = 0
    best = None
    while used < budget:
        k = min(opt.population_size, budget - used)
        xs = [opt.ask() for _ in range(opt.population_size)]
        x = torch.as_tensor(np.stack(xs[:k]), dtype=lower.dtype, device=lower.device)
        config = torch.addcmul(lower, span, x)
        with torch.inference_mode():
            ev = env.evaluate(config)
            r = reward_fn(ev, torch.arange(used + 1, used + k + 1, device=lower.device))
        j = int(torch.argmax(r))
        if best is None or float(r[j]) > best[2]:
            best = (config[j].clone(), _take(ev, j), float(r[j]), used + j + 1)
        if float(r[j]) > threshold:
            return CMAESOutcome(best[0], best[1], best[2], used + j + 1, True)
        used += k
        if k < opt.population_size:
            break
        opt.tell([(xi, -float(ri)) for xi, ri in zip(xs, r.tolist(), strict=False)])
        if opt.should_stop():  # converged: restart around the best with the initial step size
            opt = CMA(mean=((best[0] - lower) / span).clamp(0, 1).double().cpu().numpy(), sigma=sigma,
                      bounds=np.stack([np.zeros(n), np.ones(n)], axis=1), seed=seed + used)
    return CMAESOutcome(best[0], best[1], best[2], min(used, budget), best[2] > threshold if math.isfinite(best[2])
                        else False)


def _take(ev: Evaluation, j: int) -> Evaluation:
    return Evaluation(**{k: v[j:j + 1].clone() for k, v in ev.tensors().items()})
