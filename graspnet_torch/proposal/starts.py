"""Where the trials of a search start when ``solver.start: proposal``: a proposal model's K
configurations per problem, ranked by the environment's own evaluation."""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.proposal.model import PostureProposal
from graspnet_torch.solver.environment import Environment

__all__ = ["proposal_starts"]

COLLISION_PENALTY_M = 1.0  # a proposal that collides ranks after every clear one


def proposal_starts(model: PostureProposal, env: Environment, trials: int) -> Tensor:
    """(T, n) the trials' starts, in the environment's search variables and dtype, within its
    bounds: each problem's K proposals are evaluated by the environment (its error, a collision
    counted as 1 m) and trial j of a problem starts at its j-th best (the K-th best repeats from
    the best). ``trials``: T, every trial of the environment (a batch: its problems' runs)."""
    targets, mask = env.proposal_input()
    P = 1 if env.problem_index is None else int(env.problem_index.max()) + 1
    runs = trials // P
    first = torch.arange(P) * runs if env.problem_index is not None else torch.zeros(1, dtype=torch.long)
    with torch.inference_mode():
        configs, _ = model(targets[first.clamp(max=targets.shape[0] - 1)], mask[first.clamp(max=mask.shape[0] - 1)])
        K, n = configs.shape[1], configs.shape[2]
        lo, hi = (b.reshape(-1, n)[first.clamp(max=b.reshape(-1, n).shape[0] - 1)].cpu().float() for b in
                  (env.lower, env.upper))
        cand = torch.minimum(torch.maximum(configs, lo.unsqueeze(1)), hi.unsqueeze(1)).to(env.lower)  # (P, K, n)
        rows = None if env.problem_index is None else first.repeat_interleave(K).to(env.lower.device)
        ev = env.evaluate(cand.reshape(P * K, n), rows)
        score = ev.error.float().cpu()
        if ev.collisions is not None:
            score = score + COLLISION_PENALTY_M * (ev.collisions.cpu() > 0).float()
        settled = ev.config.reshape(P, K, n)  # where the environment settled them (a gripper's settling steps)
        order = score.view(P, K).argsort(1)  # (P, K)
        pick = order[:, torch.arange(runs) % K]  # (P, runs)
        starts = settled.gather(1, pick.to(settled.device).unsqueeze(-1).expand(P, runs, n))
    return starts.reshape(P * runs, n).clone()
