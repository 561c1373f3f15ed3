"""``solver=dls``: damped least squares over the whole configuration, from random restarts.

Each trial is one restart: the whole configuration x (a free hand: the palm pose and the contact
fingers' free joints; a hand on an arm: the arm's joints and those fingers; a gripper: its body
joints, both pairings of eq. 26-28 at once) drawn uniformly within the bounds and joint limits,
then Levenberg-Marquardt (:mod:`graspnet_torch.least_squares`, float64, analytic
Jacobian) puts the fingertips (gripper points) on the contacts: every step kept only where it
lowers the error and, with a collision-shaped reward (R2-R4) and something to collide with, does
not raise the collision proxy's count. A restart stops once its error is below
``solver.polish.tolerance_mm`` (a problem once ``solver.stop`` restarts have), or after
``max_iterations`` steps. It minimises the model's error directly and never sees the
reinforcement, so it is refused with sensor noise; the reported reinforcement and success are
the reward's of what it found, as for every solver.
"""

from __future__ import annotations

import time

import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.rewards import Reward, r1
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.environment import Environment
from graspnet_torch.solver.loop import LoopOutcome
from graspnet_torch.solver.tracker import enough_succeeded

__all__ = ["run_dls"]


def run_dls(env: Environment, trials: int, seed: int, solver: SolverCfg | None = None,
            reward: RewardCfg | None = None, noise: NoiseCfg | None = None, start: Tensor | None = None
            ) -> LoopOutcome:
    """``trials`` Levenberg-Marquardt restarts on one environment (a batch of problems:
    ``env.problem_index``). The history holds each restart's error (and reinforcement) per step.
    ``start``: (trials, m) the whole configurations to start from (a warm start,
    :meth:`~graspnet_torch.solver.environment.Environment.whole_of`), instead of random ones."""
    solver = solver or SolverCfg(method="dls")
    if noise is not None and noise.sigma > 0:
        raise ConfigError("solver=dls minimises the model's fingertip error and never sees the reinforcement, so "
                          "sensor noise (noise.sigma > 0) does not apply to it: use solver=srv or solver=cmaes")
    reward_fn = Reward(reward or RewardCfg(), solver.max_iterations, env.reward_base)
    like = env.lower
    gen = torch.Generator().manual_seed(seed)
    pid = None if env.problem_index is None else env.problem_index.cpu()
    done = None
    if solver.stop is not None:
        def done(converged: Tensor) -> Tensor:
            return enough_succeeded(converged, pid, solver.stop)
    trace: list[Tensor] | None = [] if solver.history else None
    t0 = time.perf_counter()
    with torch.inference_mode():
        x0 = env.random_whole(trials, gen) if start is None else start
        solved = env.local_solve(x0, solver.max_iterations, solver.polish.tolerance_mm / 1000, done, trace)
        config, evaluation = env.whole_result(solved, like)
        steps = solved.steps.clamp(min=1).to(like.device)
        r = reward_fn(evaluation, steps)
    wall = time.perf_counter() - t0
    threshold = solver.stop_threshold
    success = r > threshold if threshold is not None else torch.zeros_like(r, dtype=torch.bool)
    history = None
    if trace:
        total = torch.stack(trace)  # (K, T), metres
        history = {"total": total, "reinforcement": r1(total, reward_fn.cfg.a),  # R1 of the error (eq. 14)
                   "time": torch.linspace(0, wall, len(trace), dtype=torch.float64)}
    return LoopOutcome(config=config.clone(), evaluation=evaluation.clone(), reinforcement=r.clone(),
                       iterations=steps.clone(), success=success, wall_time_s=wall, history=history,
                       start=x0[:, : env.n].to(like))
