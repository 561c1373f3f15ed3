"""A posture proposal model seen through the environment contract: where the trials of a search
start when ``solver.start: proposal`` (a model's K configurations per problem, ranked by the
environment's own evaluation) and the data a model learns from (random posed problems, each with
its environment's view of the targets and the configuration of the posture that made it). The
model and its checkpoints: :mod:`graspnet_torch.proposal`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.proposal.data import ProposalData
from graspnet_torch.proposal.model import PostureProposal
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.environment import Environment, Evaluation
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.loop import Starts
from graspnet_torch.tasks.random import random_posed_problem

__all__ = ["Proposals", "proposal_data", "proposal_starts", "proposals"]

COLLISION_PENALTY_M = 1.0  # a proposal that collides ranks after every clear one


@dataclass
class Proposals:
    """A proposal model's answer for the problems of an environment.

    Attributes:
        config: (P, K, n) each problem's K proposals in the environment's search variables and
            dtype, within its bounds.
        score: (P, K) the model's score of each (its predicted log error: lower is better).
        first: (P,) the first row (trial) of each problem in the environment, or None (one problem).
    """

    config: Tensor
    score: Tensor
    first: Tensor | None


def proposals(model: PostureProposal, env: Environment) -> Proposals:
    """Each problem's K proposals and their scores (:class:`Proposals`)."""
    targets, mask = env.proposal_input()
    P = 1 if env.problem_index is None else int(env.problem_index.max()) + 1
    first = None if env.problem_index is None else torch.arange(P) * (targets.shape[0] // P)
    rows = torch.zeros(1, dtype=torch.long) if first is None else first
    with torch.inference_mode():
        configs, score = model(targets[rows], mask[rows])
        configs = env.proposal_configs(configs, rows)
        n = configs.shape[-1]
        lo, hi = (b.reshape(-1, n)[rows if b.dim() == 2 else 0].reshape(-1, 1, n).cpu().to(configs)
                  for b in (env.lower, env.upper))
        return Proposals(torch.minimum(torch.maximum(configs, lo), hi).to(env.lower), score, first)


def proposal_starts(model: PostureProposal, env: Environment, trials: int,
                    observe: Callable[[Evaluation], Tensor] | None = None, keep: int | None = None,
                    colliding_random: bool = True) -> Starts:
    """The trials' starts (``config`` (T, n) in the environment's search variables and dtype,
    within its bounds): each problem's K proposals (:func:`proposals`) are evaluated by the
    environment and ranked, and trial j of a problem starts at its j-th best of the ``keep`` best
    (None: all K; then from the best again). With ``colliding_random``, a proposal the
    environment finds colliding (the model does not see objects and obstacles) is no start: that
    trial starts at random, as the paper's do (``given`` False). ``trials``: T, every trial of the
    environment (a batch: its problems' runs).

    Ranked by ``observe(evaluation)`` -> (B,) the reinforcement the search would observe (with
    sensor noise: what it senses, each proposal one observation), highest first; None: by the
    model's error, a collision counted as 1 m, lowest first; where the environment counts no
    collisions and nothing is observed, by the model's own score, unevaluated (the loop
    evaluates the starts as its first iteration: on 1000 random hand problems, T = 2, as many
    land as from the evaluated ranking, at 1.5x the problems per second)."""
    props = proposals(model, env)
    cand, first = props.config, props.first
    P, K, n = cand.shape
    runs = trials // P
    if observe is None and not env.counts_collisions:
        with torch.inference_mode():
            pick = props.score.argsort(1)[:, torch.arange(runs) % min(K, keep or K)]
            starts = cand.gather(1, pick.to(cand.device).unsqueeze(-1).expand(P, runs, n))
        return Starts(config=starts.reshape(P * runs, n).clone(), given=torch.ones(P * runs, dtype=torch.bool))
    with torch.inference_mode():
        rows = None if first is None else first.repeat_interleave(K).to(env.lower.device)
        ev = env.evaluate(cand.reshape(P * K, n), rows)
        if observe is not None:
            score = -observe(ev).float().cpu()
        else:
            score = ev.error.float().cpu()
            if ev.collisions is not None:
                score = score + COLLISION_PENALTY_M * (ev.collisions.cpu() > 0).float()
        settled = ev.config.reshape(P, K, n)  # where the environment settled them (a gripper's settling steps)
        order = score.view(P, K).argsort(1)  # (P, K)
        pick = order[:, torch.arange(runs) % min(K, keep or K)]  # (P, runs)
        starts = settled.gather(1, pick.to(settled.device).unsqueeze(-1).expand(P, runs, n))
        clear = torch.ones(P, K, dtype=torch.bool) if ev.collisions is None else (ev.collisions.cpu() == 0).view(P, K)
        given = clear.gather(1, pick) | (not colliding_random)
    return Starts(config=starts.reshape(P * runs, n).clone(), given=given.reshape(P * runs))


def proposal_data(robot: Robot, finger_ik: FingerIK | None, n: int, seed: int, solver: SolverCfg | None = None
                  ) -> ProposalData:
    """n samples from :func:`~graspnet_torch.tasks.random.random_posed_problem` (seeds ``seed``,
    ``seed + 1``, ...): each problem's environment (built with ``solver``'s settings) gives the
    targets in its frame and the posture's configuration in its search variables
    (:meth:`~graspnet_torch.solver.environment.Environment.whole_of`)."""
    solver = solver or SolverCfg()
    targets, masks, configs = [], [], []
    for k in range(n):
        problem, posture = random_posed_problem(robot, seed + k)
        env = build_environment(robot, problem, finger_ik, solver)
        t, m = env.proposal_input()
        targets.append(t[0])
        masks.append(m[0])
        configs.append(env.whole_of(posture)[0, : env.n].float())
    return ProposalData(torch.stack(targets), torch.stack(masks), torch.stack(configs))
