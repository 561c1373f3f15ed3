"""``gt.solve``: the hand posture solver end to end."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import torch

from graspnet_torch.fcnn.checkpoint import load_finger_ik
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.rewards import r1
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.solver.loop import LoopOutcome, run_loop
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.srv.network import SRVNetCfg
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["polish", "robot_and_ik", "solve"]

DTYPES = {"float32": torch.float32, "float64": torch.float64}


@lru_cache(maxsize=8)
def robot_and_ik(robot_name: str) -> tuple[Robot, FingerIK]:
    """The shipped robot and its trained FCNN (cached per process)."""
    robot = Robot.from_config(robot_name)
    return robot, load_finger_ik(robot)


def solve(problem: GraspProblem | str | Path, *, trials: int = 20, seed: int = 0, max_iterations: int | None = None,
          solver: SolverCfg | None = None, srv: SRVNetCfg | None = None, reward: RewardCfg | None = None,
          noise: NoiseCfg | float | None = None, robot: Robot | None = None, finger_ik: FingerIK | None = None,
          device: str | torch.device = "cpu") -> GraspResult:
    """Find the palm pose and finger joints that put each fingertip on its contact.

    Args:
        problem: a :class:`GraspProblem`, a problem file path, or the name of a shipped task.
        trials: independent learners run as one batch; the result reports each and the best.
        seed: all randomness (initial weights, random starts, exploration, sensor noise).
        max_iterations: overrides ``solver.max_iterations``.
        solver, srv, reward, noise: settings (defaults: the paper's); ``noise`` may be sigma_n.
        robot, finger_ik: override the shipped robot and its trained FCNN.
    """
    if not isinstance(problem, GraspProblem):
        p = Path(str(problem))
        problem = GraspProblem.from_file(p) if p.suffix or p.exists() else GraspProblem.from_task(str(problem))
    solver = solver or SolverCfg()
    if max_iterations is not None:
        solver = SolverCfg(**{**solver.__dict__, "max_iterations": int(max_iterations)})
    srv, reward = srv or SRVNetCfg(), reward or RewardCfg()
    noise = NoiseCfg(float(noise)) if isinstance(noise, int | float) else (noise or NoiseCfg())
    if robot is None or finger_ik is None:
        shipped_robot, shipped_ik = robot_and_ik(problem.robot)
        robot = robot or shipped_robot
        finger_ik = finger_ik or shipped_ik
    env = HandEnvironment(robot, problem, finger_ik, solver.refine, solver.candidates, DTYPES[solver.dtype], device)
    outcome = run_loop(env, trials, seed, solver, srv, reward, noise)
    if solver.final_refine > 0:
        outcome.joints = polish(env, outcome.config, outcome.joints, solver.final_refine)
    trial_results = _report(robot, problem, outcome, reward, solver)
    settings = {"trials": trials, "max_iterations": solver.max_iterations, "threshold": solver.threshold,
                "refine": solver.refine, "final_refine": solver.final_refine, "reward_a": reward.a,
                "noise_sigma": noise.sigma, "sigma_scale": srv.sigma.scale}
    return GraspResult(robot=robot.name, trials=trial_results, problem=problem.name or problem.source, seed=seed,
                       settings=settings, outcome=outcome)


def polish(env: HandEnvironment, config: torch.Tensor, joints: torch.Tensor, iterations: int) -> torch.Tensor:
    """Refine the finger joints of reported configurations (palm poses kept); never worse."""
    with torch.inference_mode():
        targets = env.targets(config)
        q, _ = env.ik.refine(joints, targets, env.fingers, iterations)
    return q.clone()


def _report(robot: Robot, problem: GraspProblem, outcome: LoopOutcome, reward: RewardCfg,
            solver: SolverCfg) -> list[TrialResult]:
    """Per-trial results, errors recomputed in float64 by FK of the reported configuration.

    The loop runs in float32, whose rounded limits can exceed the exact ones by ~1e-7 rad; the
    reported configuration is clamped to the exact (float64) bounds and limits first.
    """
    bounds = problem.bounds()
    palm = outcome.config.detach().to(torch.float64).cpu()
    palm = torch.clamp(palm, torch.as_tensor(bounds.lower), torch.as_tensor(bounds.upper))
    T = palm.shape[0]
    idx = [robot.finger_index(f) for f in problem.fingers]
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = robot.home_posture(torch.float64).fingers.expand(T, -1, -1).clone()
    q[:, idx] = torch.clamp(outcome.joints.detach().to(torch.float64).cpu(), flo[idx], fhi[idx])
    tips = robot.fingertips_world(palm, q)[:, idx]
    contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)
    err = torch.linalg.vector_norm(tips - contacts, dim=-1)  # (T, F), metres
    total = err.sum(1)
    r = r1(total, reward.a)
    threshold = math.inf if solver.stop_threshold is None else solver.stop_threshold
    deg = 180.0 / math.pi
    results = []
    for t in range(T):
        joints = {f: [v * deg for v in q[t, k].tolist()] for k, f in enumerate(robot.finger_names)}
        pose = palm[t].tolist()
        results.append(TrialResult(
            success=bool(r[t] > threshold),
            palm_pose=pose[:3] + [a * deg for a in pose[3:]],
            joints=joints,
            fingertip_error_mm={f: float(err[t, k]) * 1000 for k, f in enumerate(problem.fingers)},
            total_error_mm=float(total[t]) * 1000,
            iterations=int(outcome.iterations[t]),
            reinforcement=float(r[t]),
            wall_time_s=outcome.wall_time_s,
        ))
    return results
