"""Solve a grasp from the command line: the main job.

Resolves the problem (a file or a shipped task), validates everything before any work, runs
``gt.solve``, prints a per-trial table and a summary, writes the result JSON (atomically),
TensorBoard curves, a picture of the best posture with the object and contacts, and the learning
curves (like the paper's Fig. 3).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ConfigError, ProblemError, say
from graspnet_torch.files import check_output_path
from graspnet_torch.io import atomic_write_text, json_digest
from graspnet_torch.jobs.configs import SolveGraspJobCfg, check_device, check_solve_memory
from graspnet_torch.jobs.verify import check_verify, motion_line, no_motion, verify_result
from graspnet_torch.motion import ReachCfg, Trajectory, check_start, plan_reach
from graspnet_torch.paths import configs_dir
from graspnet_torch.proposal import proposal_of
from graspnet_torch.robot.chain import UrdfModel
from graspnet_torch.robot.config import RobotCfg, robot_cfg_from_setting
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.settings import build, clip, unset, with_defaults
from graspnet_torch.solver.api import DTYPES, robot_and_ik, solve, starts_from_proposals, trial_posture
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.contact import contact_model
from graspnet_torch.solver.defaults import check_solver_defaults
from graspnet_torch.solver.environment import Evaluation
from graspnet_torch.solver.environments import build_environment, environment_class
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.srv.network import SRVNetCfg
from graspnet_torch.table import format_table
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz import plot_learning_curves, render_robot
from graspnet_torch.viz.motion import write_reach_gif
from graspnet_torch.viz.result import posture_panels

__all__ = ["check_problem", "hparams_of", "job_settings", "log_hparams", "log_tensorboard", "posture_of",
           "prepare_solve", "resolve_problem", "solve_grasp", "warn_on_failure", "with_robot_defaults",
           "write_pictures"]


def resolve_problem(problem: str | None, task: Mapping[str, Any] | str | None, robot: str | RobotCfg | None,
                    allow_outside_paths: bool = False) -> GraspProblem:
    """The problem file if given, else the task (a task name, or a task config as composed by
    Hydra from ``configs/task/``); checks that an explicit robot agrees. A robot config (the
    ``robot`` group as composed, overrides included) replaces the shipped one of its name: an
    override of ``robot.palm_bounds`` changes the search space."""
    robot_cfg = robot if isinstance(robot, RobotCfg) else None
    name = robot_cfg.name if robot_cfg is not None else robot
    if problem:
        result = GraspProblem.from_file(problem, robot_cfg=robot_cfg, allow_outside_paths=allow_outside_paths)
    elif isinstance(task, str):
        result = GraspProblem.from_task(task, robot_cfg=robot_cfg)
    elif isinstance(task, Mapping):
        task_name = task.get("name", "task")
        result = GraspProblem.from_mapping(task, source=f"configs/task/{clip(str(task_name), 80)}.yaml",
                                           robot_cfg=robot_cfg, folder=configs_dir() / "task",
                                           allow_outside_paths=allow_outside_paths)
    else:
        raise ProblemError("nothing to solve: give problem=PATH or task=NAME")
    if name and name != result.robot:
        raise ProblemError(f"{result.source}: the problem is for robot '{result.robot}', but robot={clip(name, 80)} "
                           f"was given")
    if robot_cfg is not None:
        result = replace(result, robot_cfg=robot_cfg)
    return result


def posture_of(robot, trial: TrialResult):
    """The :class:`~graspnet_torch.robot.Posture` of a reported trial (degrees -> radians)."""
    return trial_posture(robot, trial)


def log_tensorboard(log_dir: Path, result: GraspResult, fingers: tuple[str, ...],
                    every: int = SolveGraspJobCfg.log_every) -> None:
    """Per trial: reinforcement, total and per-finger error, what the solver has of expected
    reinforcement and mean sigma (SRV) or step size (CMA-ES) and, when it counted them (rewards
    R2-R4 with an object or obstacles), collisions; x: the iteration (CMA-ES: evaluations used).

    Every value of a logged iteration goes in one event (a summary with one value per tag, as
    ``add_scalar`` writes them one event each): the same curves, about 20x fewer writes."""
    history = result.outcome.history if result.outcome is not None else None
    if history is None:
        return
    from tensorboard.compat.proto.summary_pb2 import Summary
    from torch.utils.tensorboard.writer import FileWriter

    h = {key: value.double().numpy() for key, value in history.items()}
    K, T = h["total"].shape
    steps = h["iteration"].astype(int).tolist() if "iteration" in h else list(range(1, K + 1))
    curves = [(key, name, 1.0) for key, name in (("reinforcement", "reinforcement"),
                                                   ("expected", "expected_reinforcement"), ("sigma", "sigma_mean"),
                                                   ("step_size", "cmaes_step_size"))  # what the solver has
              if key in h] + [("total", "total_error_mm", 1000.0)]
    if "collisions" in h:
        curves.append(("collisions", "collisions", 1.0))
    writer = FileWriter(str(log_dir))
    try:
        for k in list(range(0, K, every)) + ([K - 1] if (K - 1) % every else []):
            values = []
            for t in range(T):
                tag = f"trial_{t:02d}"
                values += [Summary.Value(tag=f"{tag}/{name}", simple_value=float(h[key][k, t] * scale))
                           for key, name, scale in curves]
                if "errors" in h:
                    values += [Summary.Value(tag=f"{tag}/error_mm/{finger}",
                                             simple_value=float(h["errors"][k, t, f] * 1000))
                               for f, finger in enumerate(fingers)]
            writer.add_summary(Summary(value=values), steps[k])
    finally:
        writer.close()


def hparams_of(result: GraspResult, overrides: Sequence[str] = ()) -> tuple[dict, dict]:
    """The settings of a job (its command-line ``overrides`` as ``key=value``, numbers parsed,
    over the solver, seed, trials, noise sigma and reward slope it ran with) and its metrics
    (success, best error in mm, iterations, wall time, collisions): TensorBoard's hparams."""
    settings = result.settings
    hp: dict[str, Any] = {"solver": settings.get("solver", SolverCfg.method),  # a result without them: the defaults
                          "seed": result.seed if result.seed is not None else 0,
                          "trials": settings.get("trials", len(result.trials)),
                          "noise_sigma": settings.get("noise_sigma", NoiseCfg.sigma),
                          "reward_a": settings.get("reward_a", RewardCfg.a)}
    for item in overrides:
        key, sep, value = str(item).partition("=")
        if not sep or key.startswith(("hydra", "~")):
            continue
        try:
            hp[key.lstrip("+")] = float(value) if any(c in value for c in ".eE") else int(value)
        except ValueError:
            hp[key.lstrip("+")] = value
    best = result.best
    metrics = {"hparam/success": float(result.success), "hparam/error_mm": float(best.error_mm),
               "hparam/iterations": float(best.iterations), "hparam/wall_time_s": float(best.wall_time_s),
               "hparam/collisions": float(best.collisions)}
    return hp, metrics


def log_hparams(log_dir: Path, result: GraspResult, overrides: Sequence[str] = ()) -> None:
    """TensorBoard hparams of the job (:func:`hparams_of`), in the job's own log folder."""
    from torch.utils.tensorboard import SummaryWriter

    hp, metrics = hparams_of(result, overrides)
    with SummaryWriter(str(log_dir)) as writer:
        writer.add_hparams(hp, metrics, run_name=".")


def _trial_table(robot, result: GraspResult, fingers: tuple[str, ...], max_rows: int = 30) -> str:
    """One row per trial (the first ``max_rows``; the result JSON has them all)."""
    env = environment_class(robot)
    columns = [env.columns(t, fingers) for t in result.trials[:max_rows]]
    headers = ["trial", "success", "iterations", *(columns[0] if columns else ()), "collisions", "reinforcement"]
    rows = [[k, "yes" if t.success else "no", t.iterations, *c.values(), t.collisions, round(t.reinforcement, 5)]
            for k, (t, c) in enumerate(zip(result.trials, columns, strict=False))]
    more = len(result.trials) - max_rows
    return format_table(headers, rows, floatfmt=".3g") + (f"\n... {more} more trials in the result" if more > 0 else "")


def job_settings(cfg: Mapping[str, Any] | SolveGraspJobCfg) -> tuple[SolveGraspJobCfg, dict, RobotCfg | str | None]:
    """The job's settings as given (a group's null: the robot's default, applied later by
    :func:`with_robot_defaults`), the groups as given, and the robot setting (a config, a name or None)."""
    groups = {}
    if isinstance(cfg, Mapping):  # null in a group's YAML: the robot's default (srv.lr_bp, reward.kind, ...)
        classes = {"srv": SRVNetCfg, "reward": RewardCfg, "solver": SolverCfg}
        groups = {name: dict(cfg.get(name) or {}) for name in classes}
        cfg = {**cfg, **{name: unset(cls, groups[name]) for name, cls in classes.items()}}
    job = build(SolveGraspJobCfg, cfg)
    robot = job.robot
    if isinstance(robot, Mapping):  # the robot group, as composed (overrides included), or robot=PATH
        robot = robot_cfg_from_setting(robot, job.allow_outside_paths)
    return job, groups, robot


def with_robot_defaults(job: SolveGraspJobCfg, groups: dict, robot_cfg: RobotCfg
                        ) -> tuple[SolveGraspJobCfg, SolverCfg]:
    """The settings with the robot's ``solver_defaults`` where the job leaves them open, and the
    solver settings with ``max_iterations`` applied; refuses what cannot go together (and a
    robot's ``solver_defaults`` its groups do not allow)."""
    check_solver_defaults(robot_cfg)
    defaults = robot_cfg.solver_defaults
    job = replace(job, srv=with_defaults(SRVNetCfg, groups.get("srv", job.srv), defaults.get("srv"), "srv"),
                  reward=with_defaults(RewardCfg, groups.get("reward", job.reward), defaults.get("reward"), "reward"),
                  solver=with_defaults(SolverCfg, groups.get("solver", job.solver), defaults.get("solver"), "solver"))
    solver = job.solver
    if solver.method == "dls" and job.noise.sigma > 0:
        raise ConfigError(f"solver=dls with noise.sigma={job.noise.sigma:g}: damped least squares minimises the "
                          f"model's error and never sees the (noisy) reinforcement; use solver=srv or solver=cmaes")
    if job.max_iterations is not None:
        solver = replace(solver, max_iterations=job.max_iterations)
    return job, solver


def check_problem(problem: GraspProblem, solver: SolverCfg) -> None:
    """The checks of one problem that need its robot: collision meshes found and readable (when
    it has something to collide with), the robot and its FCNN checkpoint loaded (cached), its
    posture proposal model where the search starts from it (cached), every contact within reach,
    a gripper's approach within its limits, the contact model possible (``surface``: an object
    and fingers with pads)."""
    rc = problem.robot_cfg
    if problem.object is not None or problem.obstacles or rc.floor is not None or rc.self_collision:
        link_shapes(UrdfModel(rc.urdf, rc.mesh_roots, rc.allow_outside_paths), "collision")
    robot, _ = robot_and_ik(problem.robot_cfg)  # the robot and its FCNN checkpoint (refused if corrupted); cached
    if solver.method == "srv" and not robot.shared.names and starts_from_proposals(robot, [problem], solver):
        proposal_of(robot)  # its posture proposal model, if it has one (refused if corrupted); cached
    environment_class(robot).check(robot, problem, solver)  # every contact within reach; a gripper's approach
    contact_model(robot, problem, solver)  # solver.contact_model=surface needs an object and pads


def prepare_solve(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path
                  ) -> tuple[SolveGraspJobCfg, GraspProblem, torch.device, Path, SolverCfg]:
    """Every check of the job, before any work and without writing anything: the settings, the
    device, the problem, the output path, the memory the solve needs, and the robot's URDF and
    FCNN checkpoint (loaded once per process, so the job reuses them).

    Returns:
        the settings, the problem, the device, the result path and the solver settings (with
        ``max_iterations`` applied).
    """
    job, groups, robot = job_settings(cfg)
    if job.sequence:
        raise ConfigError("sequence=true solves the frames of a sequence: give problem=FOLDER or problem=FRAMES.jsonl")
    device = check_device(job.device)
    problem = resolve_problem(job.problem, job.task, robot, job.allow_outside_paths)
    if job.verify == "physics":
        check_verify(problem)  # an object to hold, MuJoCo installed
    job, solver = with_robot_defaults(job, groups, problem.robot_cfg)
    out = check_output_path(job.out or str(Path(run_dir) / "result.json"), "out", ConfigError)
    check_solve_memory(job.trials, solver.max_iterations, len(problem.contacts), solver.history,
                       4 if solver.dtype == "float32" else 8, device, job.srv.hidden, solver.history_postures)
    check_problem(problem, solver)
    if job.reach.enabled or problem.start:
        check_start(robot_and_ik(problem.robot_cfg)[0], problem)  # a known joint, within limits, clear
    return job, problem, device, out, solver


def solve_grasp(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path,
                overrides: Sequence[str] = ()) -> GraspResult:
    """The job behind ``scripts/solve_grasp.py``; ``cfg`` is the composed Hydra config as a dict.

    Everything is checked before any work (settings, device, problem, output path, memory); a
    refusal is a :class:`~graspnet_torch.errors.GraspnetError` and writes nothing. The result is
    written only if finite; pictures and TensorBoard (curves, and the hparams of the job: its
    command-line ``overrides`` against its metrics, for sweeps) come after it and only warn if
    they fail.
    """
    job, problem, device, out, solver = prepare_solve(cfg, run_dir)
    run_dir = Path(run_dir)
    torch.set_num_threads(job.threads)
    robot, ik = robot_and_ik(problem.robot_cfg)
    trials = job.trials
    result = solve(problem, trials=trials, seed=job.seed, solver=solver, srv=job.srv, reward=job.reward,
                   noise=job.noise, robot=robot, finger_ik=ik, device=device)
    fingers = problem.fingers
    best = result.best
    print(_trial_table(robot, result, fingers))
    n_ok = sum(t.success for t in result.trials)
    errors = np.array([t.error_mm for t in result.trials])
    clear = ", collision-free" if any(t.collisions for t in result.trials) or _has_environment(robot, problem) else ""
    stops = f"{n_ok}/{trials} trials succeeded (within {solver.tolerance_mm:g} mm{clear})"
    if best.contact_model == "surface":  # the pads: on the contacts, facing in, nothing inside
        stops = (f"{n_ok}/{trials} trials succeeded (pads within {solver.tolerance_mm:g} mm of their contacts and "
                 f"{solver.normal_cone_deg:g} degrees of the normals, no link over {solver.penetration_mm:g} mm "
                 f"inside{clear})")
    if solver.stop_threshold is None:  # noise presets: a noisy signal crosses any threshold by chance
        stops += "; no stopping threshold: the trials ran their whole budget"
    elif solver.stop_rule == "reinforcement" or job.noise.sigma > 0:
        stops += f"; {sum(t.reinforcement > solver.stop_threshold for t in result.trials)} reached r > " \
                 f"{solver.stop_threshold:g}"
    if solver.stop is not None and solver.stop < trials and solver.stop_threshold is not None:
        plural = "es" if solver.stop > 1 else ""
        stops += f" (solver.stop={solver.stop}: the problem ends at {solver.stop} success{plural})"
    free = sum(t.collisions == 0 for t in result.trials)
    quality = f"best {environment_class(robot).summary(best, fingers)}"
    if best.contact_model == "surface":
        pads = ", ".join(f"{f} {best.pad_distance_mm[f]:.3f} mm / {best.normal_angle_deg[f]:.0f} deg" for f in fingers)
        quality = f"best pads {pads}, deepest link {best.penetration_mm:.2f} mm"
    print(f"\n{problem.name or problem.source} (solver={solver.method}): {stops}; {quality}, "
          f"{best.collisions} collision(s); median {np.median(errors):.3f} mm; {free}/{trials} trials "
          f"collision-free (FCL); "
          f"{result.outcome.wall_time_s:.2f} s for {trials} trials batched")
    if result.failure is not None:
        print(f"no grasp: {result.failure}")
    if job.verify == "physics" or job.reach.enabled:  # the reported trial: the best that passes what was asked
        verification = verify_result(robot, problem, result, job.physics if job.verify == "physics" else None,
                                     job.reach if job.reach.enabled else None, job.verify_trials)
        if verification.passed:
            print(verification.summary())
        else:  # the solve worked: a warning, exit 0
            stopped = solver.stop is not None and solver.stop <= n_ok < trials
            more = f" (solver.stop={solver.stop} ended the solve at {n_ok} success(es): a larger solver.stop, or " \
                   f"null, gives more trials to check)" if stopped else ""
            say(f"warning: {verification.summary()}{more}")
    result.save(out)  # InternalError (exit 1, nothing written) if anything is not finite
    print(f"result: {out}")
    if job.tensorboard:
        warn_on_failure("TensorBoard logs", log_tensorboard, run_dir / "tb", result, fingers, every=job.log_every)
        warn_on_failure("TensorBoard hparams", log_hparams, run_dir / "tb", result, overrides)
    if job.pictures:
        warn_on_failure("pictures", write_pictures, robot, problem, result, run_dir)
    history = result.outcome.history if result.outcome is not None else None
    if history is not None and "config" in history:
        warn_on_failure("replay.json", write_replay, robot, problem, result,
                         build_environment(robot, problem, ik, solver, DTYPES[solver.dtype], device, job.reward),
                         run_dir / "replay.json")
    return result


def write_replay(robot, problem: GraspProblem, result: GraspResult, env, path: Path, frames: int = 60) -> Path:
    """``replay.json``: every trial's result fields (:meth:`Environment.report`: palm pose, joints,
    errors recomputed in float64) at up to ``frames`` iterations spread over the search, from the
    configurations and finger joints the loop recorded (``solver.history_postures``), for
    ``scripts/view.py``. ``env``: the problem's environment, built with the solve's settings."""
    history = result.outcome.history
    K = history["config"].shape[0]
    steps = sorted(set(np.linspace(0, K - 1, min(frames, K)).round().astype(int).tolist()))
    iterations = history["iteration"].tolist() if "iteration" in history else list(range(1, K + 1))
    # the replay names the result it belongs to: the fingerprint of its trials as the result file holds them
    out = {"problem": result.problem, "result": json_digest(json.loads(result.to_json())["trials"]),
           "iterations": [], "trials": []}
    for k in steps:
        config = history["config"][k].to(torch.float64)
        joints = history["joints"][k].to(torch.float64) if "joints" in history else None
        report = env.report(config, Evaluation(error=history["total"][k].to(torch.float64), joints=joints))
        out["iterations"].append(int(iterations[k]))
        out["trials"].append([{key: value for key, value in fields.items() if key != "trials"}
                              for fields in report.fields])
    return atomic_write_text(path, json.dumps(out))


def reach_motion(robot, problem: GraspProblem, result: GraspResult, cfg: ReachCfg) -> Trajectory:
    """The reach motion to the result's grasp (``reach=true``), said in one line; no grasp: no
    motion (``found`` false, the reason)."""
    motion = plan_reach(problem, result, cfg, robot) if result.success else no_motion(robot, cfg)
    print(motion_line(motion, cfg))
    return motion


def _has_environment(robot, problem: GraspProblem) -> bool:
    return has_environment(robot, problem)


def warn_on_failure(what: str, fn, *args, **kwargs) -> None:
    """Run an output step that comes after the result is written: a failure is a one-line warning
    on stderr, never a changed exit status."""
    try:
        fn(*args, **kwargs)
    except Exception as exc:  # a picture or a log must not turn a written result into a failure
        say(f"\nwarning: {what} not written: {type(exc).__name__}: {clip(' '.join(str(exc).split()), 200)}")


def write_pictures(robot, problem: GraspProblem, result: GraspResult, run_dir: Path) -> None:
    """posture.png (the best trial), learning.png (the curves) and, with a reach motion, reach.gif
    in ``run_dir``."""
    path = render_robot(robot, posture_panels(robot, problem, result), run_dir / "posture.png")
    print(f"pictures: {path}", end="")
    history = result.outcome.history if result.outcome is not None else None
    if history is not None:
        best_index = result.trials.index(result.best)
        curves = plot_learning_curves({k: v.numpy() for k, v in history.items() if k != "errors"},
                                      run_dir / "learning.png", f"{problem.name or 'problem'}: learning of "
                                      f"{len(result.trials)} trials", highlight=best_index)
        print(f", {curves}", end="")
    if result.trajectory is not None and result.trajectory.found:
        print(f", {write_reach_gif(robot, problem, result.trajectory, run_dir / 'reach.gif')}", end="")
    print()
