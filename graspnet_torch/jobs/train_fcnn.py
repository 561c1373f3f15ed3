"""Train the FCNN of every finger of a robot: progress bar, TensorBoard, resumable state,
closing accuracy table, and (``export``) the checkpoint that ``load_finger_ik`` reads."""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from graspnet_torch.errors import CheckpointError, ConfigError, Interrupted
from graspnet_torch.fcnn.checkpoint import (
    chain_fingerprint,
    load_payload,
    non_finite_tensors,
    robot_checkpoint,
    save_finger_ik,
)
from graspnet_torch.fcnn.evaluate import error_stats, heldout_targets
from graspnet_torch.fcnn.experts import ExpertSet
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.fcnn.train import FCNNTrainCfg, FingerTrainer
from graspnet_torch.files import check_output_path
from graspnet_torch.io import atomic_path
from graspnet_torch.jobs.configs import TrainFCNNJobCfg, check_train_memory
from graspnet_torch.jobs.interrupt import resume_hint, stop_on_interrupt
from graspnet_torch.robot.config import RobotCfg, robot_cfg_from_setting
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import build, clip
from graspnet_torch.table import format_table

if TYPE_CHECKING:  # pragma: no cover
    from torch.utils.tensorboard import SummaryWriter

__all__ = ["evaluate_ik", "prepare_train", "train_fcnn", "train_fcnn_job"]

STATE_FORMAT = "graspnet_torch.fcnn-train-state/1"


def evaluate_ik(ik: FingerIK, n: int = 10_000, refine: int = 3) -> list[dict]:
    """Per finger: competition alone and with ``refine`` iterations on n held-out targets."""
    rows = []
    for finger in ik.finger_names:
        lo, hi = (torch.tensor(a, dtype=torch.float32) for a in (ik.robot.fingers[finger].chain.lower,
                                                                  ik.robot.fingers[finger].chain.upper))
        _, x = heldout_targets(ik, finger, n)
        q0, e0 = ik.solve(finger, x)
        q3, e3 = ik.solve(finger, x, refine=refine)
        within = bool(((q3 >= lo - 1e-6) & (q3 <= hi + 1e-6)).all() and ((q0 >= lo - 1e-6) & (q0 <= hi + 1e-6)).all())
        rows.append({"finger": finger, "experts": ik.n_experts(finger), "competition": error_stats(e0),
                     "refined": error_stats(e3), "refine": refine, "within_limits": within})
    return rows


def _closing_table(rows: list[dict], points: dict[str, int]) -> str:
    headers = ["finger", "experts", "train points", "median mm", "p95 mm", "max mm",
               f"median mm (+{rows[0]['refine']})", "p95 mm", "max mm", "<1 mm %"]
    body = [[r["finger"], r["experts"], points.get(r["finger"], 0), r["competition"]["median_mm"],
             r["competition"]["p95_mm"], r["competition"]["max_mm"], r["refined"]["median_mm"],
             r["refined"]["p95_mm"], r["refined"]["max_mm"], round(r["refined"]["within_1mm_pct"], 2)]
            for r in rows]
    return format_table(headers, body, floatfmt=".3g")


def _cfg_signature(cfg: FCNNTrainCfg) -> dict:
    d = dataclasses.asdict(cfg)
    d.pop("epochs")  # resuming may extend training
    return d


def _save_state(path: Path, robot: Robot, cfg: FCNNTrainCfg, seed: int, trainers: dict, finished: list[str]) -> None:
    payload = {"format": STATE_FORMAT, "robot": robot.name, "seed": seed, "cfg": _cfg_signature(cfg),
               "fingerprints": {f: chain_fingerprint(robot.fingers[f].chain) for f in trainers},
               "fingers": {f: t.state_dict() for f, t in trainers.items()}, "finished": list(finished)}
    with atomic_path(path, suffix=".pt") as tmp:
        torch.save(payload, tmp)


def _load_state(path: Path, robot: Robot, cfg: FCNNTrainCfg, seed: int) -> dict:
    state = load_payload(path, STATE_FORMAT, "cannot resume, not a readable training state",
                         "cannot resume, not an FCNN training state")
    shapes = {"robot": str, "seed": int, "cfg": dict, "fingerprints": dict, "fingers": dict, "finished": list}
    wrong = [k for k, t in shapes.items() if not isinstance(state.get(k), t)]
    if wrong or not all(isinstance(f, str) for f in [*state["finished"], *state["fingers"], *state["fingerprints"]]) \
            or not all(isinstance(v, dict) for v in state["fingers"].values()):
        raise CheckpointError(f"{path}: cannot resume, malformed training state ({', '.join(wrong) or 'fingers'})")
    bad = non_finite_tensors(state.get("fingers"))
    if bad:
        raise CheckpointError(f"{path}: cannot resume, non-finite values (NaN or infinity) in {', '.join(bad[:3])}")
    if state["robot"] != robot.name or state["seed"] != seed:
        raise ConfigError(f"{path}: cannot resume, it trains robot '{state['robot']}' with seed {state['seed']}, "
                          f"not '{robot.name}' with seed {seed}")
    if state["cfg"] != _cfg_signature(cfg):
        changed = sorted(k for k in state["cfg"] if state["cfg"][k] != _cfg_signature(cfg).get(k))
        raise ConfigError(f"{path}: cannot resume with different fcnn settings ({', '.join(changed)}); "
                          f"only fcnn.epochs may change")
    for f, fp in state["fingerprints"].items():
        if f in robot.fingers and chain_fingerprint(robot.fingers[f].chain) != fp:
            raise CheckpointError(f"{path}: cannot resume, finger '{f}' of robot '{robot.name}' has changed")
    for f, finger_state in state["fingers"].items():
        _check_finger_state(path, robot, f, finger_state, cfg)
    return state


def _check_finger_state(path: Path, robot: Robot, finger: str, state: dict, cfg: FCNNTrainCfg) -> None:
    """The parts of a finger's training state that can be checked without building its trainer:
    the keys, the experts' tensors (loaded into an expert set of the finger's size) and the data."""
    where = f"{path}: cannot resume, the state of finger '{clip(finger, 40)}'"
    if finger not in robot.fingers:
        raise CheckpointError(f"{where} is not a finger of robot '{robot.name}'")
    if set(state) != {"experts", "optimizer", "data", "generator", "epochs_done"}:
        raise CheckpointError(f"{where} is malformed (keys)")
    n = robot.fingers[finger].chain.n_joints
    z3, zn = torch.zeros(3), torch.zeros(n)
    try:
        ExpertSet(n, z3, z3 + 1, zn, zn + 1, cfg.experts).load_state_dict(state["experts"])
        data = state["data"]
        x, q, owner = data["x"], data["q"], data["owner"]
        ok = (x.dim() == 2 and x.shape[1] == 3 and tuple(q.shape) == (x.shape[0], n)
              and tuple(owner.shape) == (x.shape[0],) and isinstance(state["epochs_done"], int)
              and isinstance(state["generator"], torch.Tensor) and state["generator"].dtype == torch.uint8)
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as exc:
        raise CheckpointError(f"{where} is malformed ({type(exc).__name__})") from None
    if not ok:
        raise CheckpointError(f"{where} is malformed (data shapes)")


def train_fcnn(
    robot: Robot,
    cfg: FCNNTrainCfg,
    run_dir: str | Path,
    *,
    seed: int = 0,
    fingers: list[str] | None = None,
    resume: bool = False,
    export: bool | str | Path = False,
    checkpoint_every: int = 25,
    progress: bool = True,
    eval_targets: int = 10_000,
) -> tuple[FingerIK, list[dict]]:
    """Train the experts of ``fingers`` (default: all) and return the IK and the closing table rows.

    Writes ``run_dir/state.pt`` (resumable, every ``checkpoint_every`` epochs and after each
    finger), ``run_dir/fcnn.pt`` (the trained experts), TensorBoard logs under ``run_dir/tb`` and,
    with ``export``, the checkpoint the solver reads (:func:`robot_checkpoint`; or the given path).
    """
    from torch.utils.tensorboard import SummaryWriter

    run_dir = Path(run_dir)
    fingers = list(fingers) if fingers else list(robot.finger_names)
    for f in fingers:
        robot.finger_index(f)  # clear error for unknown names
    if export:
        check_output_path(str(robot_checkpoint(robot) if export is True else export), "export", ConfigError)
    state_path = run_dir / "state.pt"
    state = _resume_state(state_path, robot, cfg, seed) if resume else None
    finished: list[str] = list(state["finished"]) if state else []
    run = _TrainRun(trainers={}, finished=finished, points={},
                    kept=f"(finished: {', '.join(finished) or 'none'})" if state else None)
    try:
        writer = SummaryWriter(str(run_dir / "tb"))
        t_start = time.perf_counter()
        try:
            for finger in fingers:
                _train_finger(run, robot, cfg, finger, seed, state, state_path, writer, progress, checkpoint_every)
        finally:
            writer.flush()
            writer.close()
        elapsed = time.perf_counter() - t_start
        ik = FingerIK(robot, {f: t.experts for f, t in run.trainers.items()})
        rows = evaluate_ik(ik, n=eval_targets)
        info = {"seed": seed, "epochs": cfg.epochs, "train_seconds": round(elapsed, 1),
                "heldout": {r["finger"]: {"competition": r["competition"], "refined": r["refined"]} for r in rows}}
        save_finger_ik(ik, run_dir / "fcnn.pt", info)
        if export:
            _export(ik, robot, export, info)
    except Interrupted:
        raise
    except KeyboardInterrupt:  # Ctrl-C outside the epochs (evaluating, exporting) or a second one
        raise Interrupted(resume_hint(state_path, run.kept)) from None
    print(f"\nFCNN of '{robot.name}' ({elapsed:.0f} s of training); errors on {eval_targets} held-out targets:")
    print(_closing_table(rows, run.points))
    return ik, rows


@dataclasses.dataclass
class _TrainRun:
    """A training run so far: each started finger's trainer, the fingers finished, their training
    points, and what the state on disk holds (for the resume hint; None: nothing saved yet)."""

    trainers: dict[str, FingerTrainer]
    finished: list[str]
    points: dict[str, int]
    kept: str | None


def _resume_state(state_path: Path, robot: Robot, cfg: FCNNTrainCfg, seed: int) -> dict | None:
    """The checked training state at ``state_path`` to resume from, or None (said so) when there is none."""
    if os.path.lexists(state_path) and not state_path.is_file():
        raise CheckpointError(f"{state_path}: cannot resume, not a regular file")
    if state_path.is_file():
        state = _load_state(state_path, robot, cfg, seed)
        print(f"resuming {state_path} (finished: {', '.join(state['finished']) or 'none'})")
        return state
    print(f"nothing to resume at {state_path}; starting a new run")
    return None


def _finger_trainer(robot: Robot, cfg: FCNNTrainCfg, finger: str, seed: int, state: dict | None,
                    state_path: Path) -> FingerTrainer:
    """The trainer of ``finger`` (seeded from ``seed`` and the finger's index), loaded from ``state``
    where it holds the finger."""
    trainer = FingerTrainer(robot.fingers[finger].chain, cfg, seed=seed + 101 * robot.finger_index(finger), name=finger)
    if state and finger in state["fingers"]:
        try:
            trainer.load_state_dict(state["fingers"][finger])
        except (KeyError, TypeError, ValueError, RuntimeError, IndexError, AttributeError) as exc:
            raise CheckpointError(f"{state_path}: cannot resume, the state of finger '{finger}' is "
                                  f"malformed ({type(exc).__name__})") from None
    return trainer


def _train_finger(run: _TrainRun, robot: Robot, cfg: FCNNTrainCfg, finger: str, seed: int, state: dict | None,
                  state_path: Path, writer: SummaryWriter, progress: bool, checkpoint_every: int) -> None:
    """Train one finger's experts up to ``cfg.epochs`` (from ``state`` where it holds the finger),
    with a progress bar; the state is saved every ``checkpoint_every`` epochs and at the end.
    Ctrl-C: stop after this epoch, save the state and raise :class:`Interrupted`."""
    from tqdm import tqdm

    trainer = _finger_trainer(robot, cfg, finger, seed, state, state_path)
    run.trainers[finger] = trainer
    bar = tqdm(total=cfg.epochs, initial=min(trainer.epochs_done, cfg.epochs), desc=f"{finger:>7s}",
               disable=None if progress else True, file=sys.stderr, dynamic_ncols=True, leave=True)
    with stop_on_interrupt() as stop:  # Ctrl-C: stop after this epoch, keep the state, say so
        while trainer.epochs_done < cfg.epochs:
            postfix = _epoch(trainer, writer, finger, cfg)
            ep = trainer.epochs_done
            bar.set_postfix(postfix)
            bar.update(1)
            if ep % checkpoint_every == 0 or stop.requested:
                _save_state(state_path, robot, cfg, seed, run.trainers, run.finished)
                run.kept = f"at epoch {ep} of {cfg.epochs} of finger '{finger}'"
            if stop.requested:
                bar.close()
                raise Interrupted(resume_hint(state_path, run.kept))
    bar.close()
    if finger not in run.finished:
        run.finished.append(finger)
    run.points[finger] = len(trainer.data)
    _save_state(state_path, robot, cfg, seed, run.trainers, run.finished)
    run.kept = f"(finished: {', '.join(run.finished)})"


def _epoch(trainer: FingerTrainer, writer: SummaryWriter, finger: str, cfg: FCNNTrainCfg) -> dict[str, Any]:
    """One training epoch of ``finger``, logged to TensorBoard (losses and points per expert, experts,
    unsolved targets; the validation errors (mm) every ``cfg.val_every`` epochs and at the last);
    returns the progress bar's postfix."""
    stats = trainer.epoch()
    ep = trainer.epochs_done
    for e, loss in enumerate(stats.get("loss", [])):
        writer.add_scalar(f"{finger}/loss/expert_{e}", loss, ep)
    for e, count in enumerate(stats["points_per_expert"]):
        writer.add_scalar(f"{finger}/points/expert_{e}", count, ep)
    writer.add_scalar(f"{finger}/experts", stats["experts"], ep)
    writer.add_scalar(f"{finger}/unsolved_targets", stats["unsolved"], ep)
    postfix: dict[str, Any] = {"experts": stats["experts"], "points": len(trainer.data)}
    if ep % cfg.val_every == 0 or ep == cfg.epochs:
        val = trainer.validate()
        writer.add_scalar(f"{finger}/val/median_mm", val["median_mm"], ep)
        writer.add_scalar(f"{finger}/val/p95_mm", val["p95_mm"], ep)
        postfix["val median mm"] = f"{val['median_mm']:.3f}"
    return postfix


def _export(ik: FingerIK, robot: Robot, export: bool | str | Path, info: dict) -> None:
    """Save the trained checkpoint where ``export`` says (True: the robot's, which the solver reads)."""
    target = robot_checkpoint(robot) if export is True else Path(export)
    save_finger_ik(ik, target, info)
    reads = Path(target).resolve() == robot_checkpoint(robot).resolve()
    print(f"exported {target}" + (f" (the checkpoint `solve_grasp.py robot={robot.cfg.cli_name}` reads)"
                                  if reads else ""))


def prepare_train(cfg: Mapping[str, Any] | TrainFCNNJobCfg,
                  run_dir: str | Path) -> tuple[TrainFCNNJobCfg, RobotCfg]:
    """Every check of the training job before any work, writing nothing: the settings, the robot
    config and its URDF (the robot is built), the export path and, with ``resume``, the training
    state in ``run_dir``."""
    job = build(TrainFCNNJobCfg, cfg)
    check_train_memory(job.fcnn, job.eval_targets)
    robot_cfg = robot_cfg_from_setting(job.robot, job.allow_outside_paths)
    if robot_cfg is None:
        raise ConfigError("robot: give robot=NAME (configs/robot/) or robot=PATH (a robot YAML) to train its fingers")
    if not robot_cfg.fingers:
        raise ConfigError(f"robot '{robot_cfg.name}' has no fingers: nothing to train")
    if job.fingers:
        unknown = [f for f in job.fingers if f not in robot_cfg.fingers]
        if unknown:
            raise ConfigError(f"robot '{robot_cfg.name}' has no finger '{clip(unknown[0], 40)}' (fingers: "
                              f"{', '.join(robot_cfg.fingers)})")
    if export_target(job, robot_cfg) is not None:
        check_output_path(str(export_target(job, robot_cfg)), "export", ConfigError)
    robot = Robot(robot_cfg)  # the URDF checked and the fingers' chains built (milliseconds), before any folder
    state_path = Path(run_dir) / "state.pt"
    if job.resume and os.path.lexists(state_path) and not state_path.is_file():
        raise CheckpointError(f"{state_path}: cannot resume, not a regular file")
    if job.resume and state_path.is_file():
        _load_state(state_path, robot, job.fcnn, job.seed)
    return job, robot_cfg


def export_target(job: TrainFCNNJobCfg, robot_cfg: RobotCfg) -> Path | None:
    """Where the job exports the trained checkpoint: ``export=PATH``; ``export=true`` (or left
    unset when every finger is trained) the robot's checkpoint, which the solver reads; None."""
    export = job.export
    if export is None:
        export = not job.fingers or set(job.fingers) >= set(robot_cfg.fingers)
    if export is False:
        return None
    return robot_checkpoint(robot_cfg) if export is True else Path(export)


def train_fcnn_job(cfg: Mapping[str, Any] | TrainFCNNJobCfg, run_dir: str | Path) -> tuple[FingerIK, list[dict]]:
    """The job behind ``scripts/train_fcnn.py``; ``cfg`` is the composed Hydra config as a dict."""
    job, robot_cfg = prepare_train(cfg, run_dir)
    torch.set_num_threads(job.threads)
    return train_fcnn(Robot(robot_cfg), job.fcnn, run_dir, seed=job.seed, fingers=job.fingers, resume=job.resume,
                      export=export_target(job, robot_cfg) or False, checkpoint_every=job.checkpoint_every,
                      progress=job.progress,
                      eval_targets=job.eval_targets)
