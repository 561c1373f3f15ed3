"""``gt.solve``: the hand posture solver end to end."""

from __future__ import annotations

import warnings
import weakref
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.checkpoint import finger_ik_of, robot_checkpoint
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.paths import configs_dir
from graspnet_torch.proposal import posture_checkpoint, proposal_of
from graspnet_torch.rewards import Reward, add_noise
from graspnet_torch.robot.config import RobotCfg, available_robots, load_robot_cfg
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import with_defaults
from graspnet_torch.solver.cmaes import run_cmaes
from graspnet_torch.solver.config import DEFAULT_TRIALS, NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.contact import off_surface
from graspnet_torch.solver.defaults import check_solver_defaults
from graspnet_torch.solver.dls import run_dls
from graspnet_torch.solver.environment import Environment
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.loop import LoopOutcome, Starts, enough_succeeded, run_loop
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.proposals import proposal_starts
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.solver.trials import trial_results
from graspnet_torch.srv.network import SRVNetCfg
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.tasks.reference import reference_posture
from graspnet_torch.threads import torch_threads

__all__ = ["as_problem", "build_environment", "finger_ik_for", "reference_posture", "result_of", "robot_and_ik",
           "robot_of", "search", "settings_of", "solve", "solve_many", "solve_with", "starts_from_proposals",
           "trial_posture"]
# build_environment, reference_posture, trial_posture: from their modules, for callers here

DTYPES = {"float32": torch.float32, "float64": torch.float64}
ROBOTS_KEPT = 8  # robots (with their FCNNs) kept built per process: shipped ones by name, others by config
PROBLEMS_KEPT = 64  # problem files kept read (one per file version)


@lru_cache(maxsize=ROBOTS_KEPT)
def _shipped_robot(robot_name: str) -> Robot:
    return Robot.from_config(robot_name)


@lru_cache(maxsize=ROBOTS_KEPT)
def _shipped_cfg(robot_name: str) -> RobotCfg:
    return load_robot_cfg(robot_name)


def robot_of(robot: str | RobotCfg) -> Robot:
    """A robot: a shipped robot by name, or a robot config (each built once per process; no
    checkpoint read); a config that differs from the shipped one of its name only in its search
    space, home posture or description reuses the shipped kinematics."""
    if isinstance(robot, str):
        return _shipped_robot(robot)
    if robot.name in available_robots():
        shipped = _shipped_cfg(robot.name)
        if all(getattr(shipped, k) == getattr(robot, k) for k in KINEMATIC_KEYS):
            return _shipped_robot(robot.name)
    key = (repr(robot), _stamp(robot.urdf))  # once per config and URDF version
    if key not in _BUILT:
        _BUILT[key] = Robot(robot)
        while len(_BUILT) > ROBOTS_KEPT:
            _BUILT.pop(next(iter(_BUILT)))
    return _BUILT[key]


def finger_ik_for(robot: Robot) -> FingerIK | None:
    """A robot's trained FCNN (None for a robot without fingers, the MANUS), read once per robot
    and checkpoint version (:func:`~graspnet_torch.fcnn.checkpoint.finger_ik_of`: a missing or
    corrupted checkpoint raises ``CheckpointError`` naming the file)."""
    if not robot.n_fingers:
        return None
    stamp = _stamp(robot_checkpoint(robot))
    kept = _IK.get(robot)
    if kept is None or kept[0] != stamp:
        kept = _IK[robot] = (stamp, finger_ik_of(robot))
    return kept[1]


def robot_and_ik(robot: str | RobotCfg) -> tuple[Robot, FingerIK | None]:
    """A robot and its trained FCNN (None for a robot without fingers, the MANUS): :func:`robot_of`
    and :func:`finger_ik_for`; a config that differs from the shipped one of its name only in its
    search space, home posture or description reuses the shipped kinematics and FCNN."""
    built = robot_of(robot)
    return built, finger_ik_for(built)


_BUILT: dict[tuple, Robot] = {}
_IK: weakref.WeakKeyDictionary[Robot, tuple] = weakref.WeakKeyDictionary()  # robot -> (checkpoint stamp, FCNN)


def _stamp(path: Path | None) -> tuple[int, int] | None:
    """A file's size and modification time (None: no such file)."""
    try:
        stat = Path(path).stat() if path is not None else None
    except OSError:
        return None
    return None if stat is None else (stat.st_size, stat.st_mtime_ns)


KINEMATIC_KEYS = ("urdf", "palm_link", "fingers", "arm", "mobile_base", "gripper_points", "floor", "self_collision",
                  "wrist")


def as_robot(robot: str | Path | RobotCfg | Robot) -> Robot:
    """A built robot, a shipped robot's name, a robot config or its YAML path -> the robot (built
    once per process, :func:`robot_of`: no checkpoint read)."""
    if isinstance(robot, Robot):
        return robot
    return robot_of(str(robot) if isinstance(robot, Path) else robot)


def as_problem(problem: GraspProblem | str | Path) -> GraspProblem:
    """A problem, a problem file or a shipped task's name -> the problem (a file read once while
    its size and modification time stay the same); one with ``contacts: auto`` is refused (its
    contacts are chosen by :func:`graspnet_torch.synthesis.synthesize_grasps`)."""
    out = _given_problem(problem)
    if out.auto is not None:
        key = "points" if out.robot_cfg is not None and out.robot_cfg.gripper_points else "contacts"
        raise ProblemError(f"{out.source}: {key}: auto: the solver needs {key}; choose them on the object "
                           f"with gt.synthesize_grasps or scripts/solve_grasp.py")
    return out


def _given_problem(problem: GraspProblem | str | Path) -> GraspProblem:
    if isinstance(problem, GraspProblem):
        return problem
    p = Path(str(problem))
    if not (p.suffix or p.exists()):

        p, task = configs_dir() / "task" / f"{problem}.yaml", str(problem)
        if not p.is_file():
            return GraspProblem.from_task(task)  # its refusal
    else:
        task = None
    try:
        stat = p.stat()
    except OSError:
        return GraspProblem.from_file(p)  # its refusal
    return _read_problem(str(p), task, stat.st_size, stat.st_mtime_ns)


@lru_cache(maxsize=PROBLEMS_KEPT)
def _read_problem(path: str, task: str | None, size: int, mtime_ns: int) -> GraspProblem:
    return GraspProblem.from_task(task) if task is not None else GraspProblem.from_file(path)


def settings_of(robot: Robot, solver: SolverCfg | None, srv: SRVNetCfg | None, reward: RewardCfg | None,
              max_iterations: int | None) -> tuple[SolverCfg, SRVNetCfg, RewardCfg]:
    """The settings of a solve: the given ones, else the robot's ``solver_defaults`` (checked: one
    line naming the robot's file), else the paper's."""
    check_solver_defaults(robot.cfg)
    defaults = robot.cfg.solver_defaults
    solver = with_defaults(SolverCfg, solver, defaults.get("solver"), "solver")
    if max_iterations is not None:
        solver = SolverCfg(**{**solver.__dict__, "max_iterations": int(max_iterations)})
    srv = with_defaults(SRVNetCfg, srv, defaults.get("srv"), "srv")
    reward = with_defaults(RewardCfg, reward, defaults.get("reward"), "reward")
    return solver, srv, reward


def _settings_dict(trials: int, solver: SolverCfg, srv: SRVNetCfg, reward: RewardCfg, noise: NoiseCfg) -> dict:
    return {"trials": trials, "max_iterations": solver.max_iterations, "threshold": solver.threshold,
            "tolerance_mm": solver.tolerance_mm, "stop_rule": solver.stop_rule,
            "stop": solver.stop, "solver": solver.method, "polish": solver.polish.mode, "reward": reward.kind,
            "reward_a": reward.a, "reward_p": reward.p if reward.p is not None else solver.max_iterations,
            "lr_bp": srv.lr_bp, "lr_srv": srv.lr_srv, "lr_lms": srv.lr_lms,
            "noise_sigma": noise.sigma, "sigma_scale": srv.sigma.scale}


def result_of(robot: Robot, problem: GraspProblem, env: Environment, outcome: LoopOutcome, trials: int, seed: int,
            solver: SolverCfg, srv: SRVNetCfg, reward: RewardCfg, noise: NoiseCfg) -> GraspResult:
    report = env.report(outcome.config, outcome.evaluation)
    results, failure = trial_results(robot, problem, env, report, outcome, reward, solver)
    return GraspResult(robot=robot.name, trials=results, problem=problem.name or problem.source, seed=seed,
                       settings=_settings_dict(trials, solver, srv, reward, noise), outcome=outcome, failure=failure)


def solve(problem: GraspProblem | str | Path, *, trials: int = DEFAULT_TRIALS, seed: int = 0,
          max_iterations: int | None = None, solver: SolverCfg | None = None, srv: SRVNetCfg | None = None,
          reward: RewardCfg | None = None, noise: NoiseCfg | float | None = None, robot: Robot | None = None,
          finger_ik: FingerIK | None = None, device: str | torch.device = "cpu", threads: int | None = None
          ) -> GraspResult:
    """Find the palm pose and finger joints that put each fingertip on its contact.

    Args:
        problem: a :class:`GraspProblem`, a problem file path, or the name of a shipped task.
        trials: independent learners run as one batch (default :data:`DEFAULT_TRIALS`); the result
            reports each and the best.
        seed: all randomness (initial weights, random starts, exploration, sensor noise).
        max_iterations: overrides ``solver.max_iterations`` (its one default; None: not overridden).
        solver: settings (so are srv, reward, noise); ``None``: the robot's (its config's
            ``solver_defaults``: the paper's section 5.1 for the hand, 6.3 for the arm) over the
            paper's defaults.
        srv: the SRV network's settings.
        reward: the reward's settings.
        noise: the sensor noise's settings, or sigma_n.
        robot: overrides the shipped robot.
        finger_ik: overrides its trained FCNN.
        threads: torch CPU threads for the work (None: the package's default, 1;
            :func:`~graspnet_torch.threads.set_default_threads`); the caller's count is put back.
    """
    with torch_threads(threads):
        problem = as_problem(problem)
        noise = NoiseCfg(float(noise)) if isinstance(noise, int | float) else (noise or NoiseCfg())
        if robot is None or finger_ik is None:
            shipped_robot, shipped_ik = robot_and_ik(problem.robot_cfg or problem.robot)
            robot = robot or shipped_robot
            finger_ik = finger_ik or shipped_ik
        solver, srv, reward = settings_of(robot, solver, srv, reward, max_iterations)
        return solve_with(robot, finger_ik, problem, trials, seed, solver, srv, reward, noise, device)


def solve_with(robot: Robot, finger_ik: FingerIK | None, problem: GraspProblem, trials: int, seed: int,
               solver: SolverCfg, srv: SRVNetCfg, reward: RewardCfg, noise: NoiseCfg,
               device: str | torch.device = "cpu") -> GraspResult:
    """:func:`solve` with everything resolved (:func:`settings_of`): the environment, the search,
    the result. ``gt.Solver`` calls this: its settings are resolved once."""
    say_off_surface(robot, [problem], solver)
    env = build_environment(robot, problem, finger_ik, solver, DTYPES[solver.dtype], device, reward)
    outcome = search(env, trials, seed, solver, srv, reward, noise)
    return result_of(robot, problem, env, outcome, trials, seed, solver, srv, reward, noise)


def search(env: Environment, trials: int, seed: int, solver: SolverCfg, srv: SRVNetCfg, reward: RewardCfg,
           noise: NoiseCfg) -> LoopOutcome:
    """``solver.method`` on one environment, then (srv, cmaes) the environment's finish (the
    fingers' refinement and the whole polish; a gripper's polish); the wall time includes it."""
    import time

    t0 = time.perf_counter()
    if solver.method == "dls":

        outcome = run_dls(env, trials, seed, solver, reward, noise)
    else:
        if solver.method == "cmaes":

            outcome = run_cmaes(env, trials, seed, solver, reward, noise)
        else:
            outcome = run_loop(env, trials, seed, solver, srv, reward, noise,
                               start=_starts(env, trials, seed, solver, reward, noise))
        done = None
        if solver.stop is not None:  # the polish, too, ends a problem once `stop` of its trials converged;
            pid = None if env.problem_index is None else env.problem_index.cpu()  # in a problem that has
            idle = None  # `stop` grasps already, only those polish on
            if solver.stop_rule == "grasp" and noise.sigma == 0:
                landed = env.grasped(outcome.evaluation, solver.tolerance_mm / 1000).cpu()
                idle = enough_succeeded(landed, pid, solver.stop) & ~landed

            def done(converged: Tensor) -> Tensor:
                enough = enough_succeeded(converged, pid, solver.stop)
                return enough if idle is None else enough | idle.to(enough.device)
        outcome.config, outcome.evaluation = env.finish(outcome.config, outcome.evaluation, done)
    outcome.wall_time_s = time.perf_counter() - t0
    return outcome


_SAID_NO_MODEL: set[str] = set()
_SAID_OFF: set[tuple] = set()


def say_off_surface(robot: Robot, problems: Sequence[GraspProblem], solver: SolverCfg) -> None:
    """Warn, once per problem and contact set, where the surface model is asked to put pads on
    contacts off the object's surface (:func:`~graspnet_torch.solver.contact.off_surface`)."""
    for problem in problems:
        key = (problem.source, solver.contact_model, np.asarray(problem.contacts_world()).round(6).tobytes())
        if key not in _SAID_OFF:
            _SAID_OFF.add(key)
            line = off_surface(robot, problem, solver)
            if line is not None:
                warnings.warn(line, stacklevel=4)


def starts_from_proposals(robot: Robot, problems: Sequence[GraspProblem], solver: SolverCfg) -> bool:
    """Whether an srv search of ``problems`` starts its trials from the robot's posture proposal
    model (when it has one): ``solver.start`` 'proposal', or 'auto' where nothing can collide."""

    return solver.start != "random" and not (solver.start == "auto" and any(has_environment(robot, p)
                                                                             for p in problems))
NOISY_RANKING_SEED = 7919  # the noisy observations that rank the proposals: their own stream
NOISY_KEPT_SHARE = 4  # with sensor noise the trials start at the best 1/NOISY_KEPT_SHARE of the K ranked proposals


def _starts(env: Environment, trials: int, seed: int, solver: SolverCfg, reward: RewardCfg, noise: NoiseCfg
            ) -> Starts | None:
    """The trials' starts (None: random within the bounds) of ``solver.start``: 'proposal', or
    'auto' where the problems have no object and no obstacles (a proposal does not see them: near
    them it lands grasps through them, measured in the experiment proposal).
    Ranked by the model's error, trial j at the j-th best; with sensor noise by one noisy
    observation of each proposal's reinforcement (the error is not observed), the trials at the
    best quarter. A proposal the environment finds colliding starts its trial (exploring widely:
    the loop places no expected reinforcement there) where the trials are restarts of one search
    (``solver.stop`` set: measured on the arm, its polish often lands clear); where every trial
    runs to its own stop (``stop: null``, independent learners) it is no start: that trial starts
    at random (measured on the MANUS, whose colliding proposals pass through the table). A robot without
    a trained posture proposal model starts at random, and its first such search says so."""
    if env.shared_slots or not starts_from_proposals(env.robot, env.problems, solver):
        return None  # (a hand whose fingers share joints: its proposals do not give them)

    model = proposal_of(env.robot)
    if model is None:
        if env.robot.name not in _SAID_NO_MODEL:
            _SAID_NO_MODEL.add(env.robot.name)
            warnings.warn(f"solver.start={solver.start}: robot '{env.robot.name}' has no posture proposal model "
                          f"({posture_checkpoint(env.robot)}); its trials start at random (train one with "
                          f"`python scripts/train_posture.py robot={env.robot.cfg.cli_name}`)", stacklevel=3)
        return None
    if noise.sigma == 0:
        return proposal_starts(model, env, trials, keep=None, colliding_random=solver.stop is None)

    reward_fn = Reward(reward, solver.max_iterations, env.reward_base)
    gen = torch.Generator(device=env.lower.device).manual_seed(seed + NOISY_RANKING_SEED)
    return proposal_starts(model, env, trials, lambda ev: add_noise(reward_fn(ev, 1), noise.sigma, gen),
                           keep=max(1, model.heads // NOISY_KEPT_SHARE), colliding_random=solver.stop is None)


def solve_many(problems: Sequence[GraspProblem | str | Path], *, trials: int = DEFAULT_TRIALS, seed: int = 0,
               max_iterations: int | None = None, solver: SolverCfg | None = None, srv: SRVNetCfg | None = None,
               reward: RewardCfg | None = None, noise: NoiseCfg | float | None = None,
               robot: Robot | None = None, finger_ik: FingerIK | None = None,
               device: str | torch.device = "cpu", threads: int | None = None) -> list[GraspResult]:
    """Solve P problems of one robot, ``trials`` learners each: one result per problem, in order.

    The P x ``trials`` learners run as one vectorised search (one network batch; for a hand, the
    union of the problems' contact fingers with a mask per trial; one collision proxy holding
    every problem's objects, so problems with obstacles need the same kinds in the same order). A
    problem ends once ``solver.stop`` of its trials have succeeded; once most trials have stopped,
    only the others are evaluated. Settings as :func:`solve`; one ``seed`` for the batch, so a
    problem's result differs from its single solve with the same seed. Each result's
    ``wall_time_s`` is the batch's time divided by P; ``threads`` as :func:`solve`.
    """
    with torch_threads(threads):
        return _solve_many(problems, trials, seed, max_iterations, solver, srv, reward, noise, robot, finger_ik,
                           device)


def _solve_many(problems: Sequence[GraspProblem | str | Path], trials: int, seed: int, max_iterations: int | None,
                solver: SolverCfg | None, srv: SRVNetCfg | None, reward: RewardCfg | None,
                noise: NoiseCfg | float | None, robot: Robot | None, finger_ik: FingerIK | None,
                device: str | torch.device) -> list[GraspResult]:
    batch = [as_problem(p) for p in problems]
    if not batch:
        return []
    noise = NoiseCfg(float(noise)) if isinstance(noise, int | float) else (noise or NoiseCfg())
    if robot is None or finger_ik is None:
        shipped_robot, shipped_ik = robot_and_ik(batch[0].robot_cfg or batch[0].robot)
        robot, finger_ik = robot or shipped_robot, finger_ik or shipped_ik
    first = batch[0]
    for p in batch[1:]:
        if p.robot != first.robot or (p.robot_cfg is not first.robot_cfg and p.robot_cfg is not None
                                      and first.robot_cfg is not None and p.robot_cfg.urdf != first.robot_cfg.urdf):
            raise ProblemError(f"{p.source}: robot '{p.robot}' differs from the batch's '{batch[0].robot}' "
                               f"(one batch, one robot)")
    if len(batch) == 1:
        return [solve(batch[0], trials=trials, seed=seed, max_iterations=max_iterations, solver=solver, srv=srv,
                      reward=reward, noise=noise, robot=robot, finger_ik=finger_ik, device=device,
                      threads=torch.get_num_threads())]  # the count this call already set
    solver, srv, reward = settings_of(robot, solver, srv, reward, max_iterations)
    say_off_surface(robot, batch, solver)
    env = build_environment(robot, batch, finger_ik, solver, DTYPES[solver.dtype], device, reward, runs=trials)
    outcome = search(env, trials * len(batch), seed, solver, srv, reward, noise)
    report = env.report(outcome.config, outcome.evaluation)
    results = []
    settings = _settings_dict(trials, solver, srv, reward, noise)
    for problem, part, part_report in zip(batch, outcome.split(trials), report.split(trials), strict=True):
        part.wall_time_s = outcome.wall_time_s / len(batch)  # the batch's time, shared out
        part_results, failure = trial_results(robot, problem, env, part_report, part, reward, solver)
        results.append(GraspResult(robot=robot.name, trials=part_results, problem=problem.name or problem.source,
                                   seed=seed, settings=dict(settings), outcome=part, failure=failure))
    return results
