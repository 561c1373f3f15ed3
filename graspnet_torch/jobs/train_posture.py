"""Train a robot's posture proposal model: data, progress bar, TensorBoard, resumable state, a
closing table on fresh problems, and (``export``) the checkpoint the solver reads."""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspnet_torch.errors import CheckpointError, ConfigError, Interrupted
from graspnet_torch.fcnn.checkpoint import finger_ik_of, load_payload, non_finite_tensors
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.files import check_output_path
from graspnet_torch.io import atomic_path
from graspnet_torch.jobs.configs import TrainPostureJobCfg
from graspnet_torch.jobs.interrupt import resume_hint, stop_on_interrupt
from graspnet_torch.proposal.checkpoint import posture_checkpoint, robot_signature, save_proposal
from graspnet_torch.proposal.data import ProposalData
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg
from graspnet_torch.proposal.train import ProposalTrainer
from graspnet_torch.robot.config import RobotCfg, robot_cfg_from_setting
from graspnet_torch.robot.kinds import robot_kind
from graspnet_torch.robot.robot import Robot
from graspnet_torch.settings import build
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.proposals import proposal_data, proposals
from graspnet_torch.table import format_table
from graspnet_torch.tasks.random import random_posed_problem

__all__ = ["evaluate_proposal", "prepare_train_posture", "train_posture", "train_posture_job"]

STATE_FORMAT = "graspnet_torch.posture-train-state/1"
EVAL_SEED = 900_000  # fresh problems for the closing table: far from the training seeds


def evaluate_proposal(model: PostureProposal, robot: Robot, finger_ik: FingerIK | None, n: int = 200,
                      seed: int = EVAL_SEED) -> dict[str, float]:
    """On n fresh random posed problems: the best of the K proposals (within bounds, evaluated by
    the environment: a hand's fingers placed by the FCNN, no iteration) against the best of K
    uniform random configurations; errors in mm (the environment's error: E of eq. 3, or d of
    eq. 26)."""
    g = torch.Generator().manual_seed(seed)
    ours, rand = [], []
    solver = SolverCfg()
    with torch.inference_mode():
        for k in range(n):
            problem, _ = random_posed_problem(robot, seed + k)
            env = build_environment(robot, problem, finger_ik, solver)
            configs = proposals(model, env).config[0]
            ours.append(float(env.evaluate(configs).error.min()) * 1000)
            r = env.lower + (env.upper - env.lower) * torch.rand(configs.shape, generator=g)
            rand.append(float(env.evaluate(r).error.min()) * 1000)
    o, r = np.asarray(ours), np.asarray(rand)
    return {"problems": n, "median_mm": float(np.median(o)), "p90_mm": float(np.percentile(o, 90)),
            "random_median_mm": float(np.median(r)), "random_p90_mm": float(np.percentile(r, 90))}


def _periodic(robot: Robot, finger_ik: FingerIK | None, seed: int) -> torch.Tensor:
    """(n,) the search variables whose bounds span a full turn (compared modulo 2 pi)."""
    env = build_environment(robot, random_posed_problem(robot, seed)[0], finger_ik, SolverCfg())
    span = (env.upper - env.lower).reshape(-1, env.n)[0]
    return span >= 2 * math.pi * (1 - 1e-6)


def _save_state(path: Path, robot: Robot, cfg: ProposalCfg, seed: int, trainer: ProposalTrainer,
                data: ProposalData) -> None:
    payload = {"format": STATE_FORMAT, "robot": robot.name, "signature": robot_signature(robot), "seed": seed,
               "cfg": _signature(cfg), "trainer": trainer.state_dict(),
               "data": {"targets": data.targets, "mask": data.mask, "configs": data.configs}}
    with atomic_path(path, suffix=".pt") as tmp:
        torch.save(payload, tmp)


def _signature(cfg: ProposalCfg) -> dict:
    return {"heads": cfg.heads, "hidden": list(cfg.hidden), "samples": cfg.samples, "batch": cfg.batch, "lr": cfg.lr}


def _load_state(path: Path, robot: Robot, cfg: ProposalCfg, seed: int) -> dict:
    state = load_payload(path, STATE_FORMAT, "cannot resume, not a readable training state",
                         "cannot resume, not a posture proposal training state")
    if state.get("robot") != robot.name or state.get("seed") != seed or \
            state.get("signature") != robot_signature(robot):
        raise ConfigError(f"{path}: cannot resume, it trains robot '{state.get('robot')}' with seed "
                          f"{state.get('seed')}, not '{robot.name}' (as it is now) with seed {seed}")
    if state.get("cfg") != _signature(cfg):
        changed = sorted(k for k, v in _signature(cfg).items() if (state.get("cfg") or {}).get(k) != v)
        raise ConfigError(f"{path}: cannot resume with different posture settings ({', '.join(changed)}); "
                          f"only posture.steps and posture.val_every may change")
    bad = non_finite_tensors(state.get("trainer"))
    if bad:
        raise CheckpointError(f"{path}: cannot resume, non-finite values (NaN or infinity) in {', '.join(bad[:3])}")
    try:
        d = state["data"]
        ok = d["targets"].dim() == 3 and d["mask"].shape == d["targets"].shape[:2] and \
            d["configs"].shape[0] == d["targets"].shape[0] and isinstance(state["trainer"]["steps_done"], int)
    except (KeyError, TypeError, AttributeError) as exc:
        raise CheckpointError(f"{path}: cannot resume, malformed training state ({type(exc).__name__})") from None
    if not ok:
        raise CheckpointError(f"{path}: cannot resume, malformed training state (data shapes)")
    return state


def train_posture(robot: Robot, finger_ik: FingerIK | None, cfg: ProposalCfg, run_dir: str | Path, *, seed: int = 0,
                  resume: bool = False, export: bool | str | Path = False, checkpoint_every: int = 1000,
                  progress: bool = True, eval_problems: int = 200) -> tuple[PostureProposal, dict]:
    """Train the robot's proposal model; returns it and the closing table's numbers.

    Writes ``run_dir/state.pt`` (resumable, every ``checkpoint_every`` steps and at the end),
    ``run_dir/posture.pt`` (the model), TensorBoard logs under ``run_dir/tb`` and, with
    ``export``, the checkpoint the solver reads (:func:`posture_checkpoint`, or the given path).
    """
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    run_dir = Path(run_dir)
    state_path = run_dir / "state.pt"
    state = _resumed(state_path, robot, cfg, seed) if resume else None
    kept = f"of step {state['trainer']['steps_done']}" if state is not None else None  # the state on disk
    try:
        t_start = time.perf_counter()
        if state is not None:
            d = state["data"]
            data = ProposalData(d["targets"], d["mask"], d["configs"])
        else:
            print(f"drawing {cfg.samples + cfg.samples // 10} random posed problems of '{robot.name}' ...",
                  flush=True)
            data = proposal_data(robot, finger_ik, cfg.samples + cfg.samples // 10, seed * 1_000_003)
        train, held = data.split(cfg.samples)
        torch.manual_seed(seed)
        model = PostureProposal(data.targets.shape[1], data.configs.shape[1], cfg)
        model.fit_scales(train.targets, train.mask, train.configs, _periodic(robot, finger_ik, seed))
        trainer = ProposalTrainer(model, train, held, cfg, seed=seed)
        if state is not None:
            trainer.load_state_dict(state["trainer"])
        writer = SummaryWriter(str(run_dir / "tb"))
        bar = tqdm(total=cfg.steps, initial=min(trainer.steps_done, cfg.steps), desc=f"{robot.name} posture",
                   disable=None if progress else True, file=sys.stderr, dynamic_ncols=True, leave=True)
        try:
            with stop_on_interrupt() as stop:  # Ctrl-C: stop after this step, keep the state, say so
                while trainer.steps_done < cfg.steps:
                    loss = trainer.step()
                    step = trainer.steps_done
                    writer.add_scalar("loss", loss, step)
                    if step % cfg.val_every == 0 or step == cfg.steps:
                        val = trainer.validate()
                        for key, value in val.items():
                            writer.add_scalar(f"val/{key}", value, step)
                        bar.set_postfix({"loss": f"{loss:.3f}", "val median": f"{val['median']:.3f}"})
                    bar.update(1)
                    if step % checkpoint_every == 0 or stop.requested:
                        _save_state(state_path, robot, cfg, seed, trainer, data)
                        kept = f"of step {step}"
                    if stop.requested:
                        raise Interrupted(resume_hint(state_path, f"{kept} of {cfg.steps}"))
            _save_state(state_path, robot, cfg, seed, trainer, data)
            kept = f"of step {trainer.steps_done} (trained; resuming evaluates and exports)"
        finally:
            bar.close()
            writer.flush()
            writer.close()
        elapsed = time.perf_counter() - t_start
        model.eval()
        table = evaluate_proposal(model, robot, finger_ik, eval_problems)
        info = {"seed": seed, "steps": cfg.steps, "samples": cfg.samples, "train_seconds": round(elapsed, 1),
                "fresh_problems": table}
        save_proposal(model, robot, cfg, run_dir / "posture.pt", info)
        if export:
            target = posture_checkpoint(robot) if export is True else Path(export)
            save_proposal(model, robot, cfg, target, info)
            print(f"exported {target}")
    except Interrupted:
        raise
    except KeyboardInterrupt:  # Ctrl-C outside the steps (drawing data, evaluating) or a second one
        raise Interrupted(resume_hint(state_path, kept)) from None
    _print_table(robot, cfg, table, elapsed, eval_problems)
    return model, table


def _resumed(state_path: Path, robot: Robot, cfg: ProposalCfg, seed: int) -> dict | None:
    """The training state to resume from (None, said, where there is none)."""
    if not state_path.is_file():
        print(f"nothing to resume at {state_path}; starting a new run")
        return None
    state = _load_state(state_path, robot, cfg, seed)
    print(f"resuming {state_path} (step {state['trainer']['steps_done']})")
    return state


def _print_table(robot: Robot, cfg: ProposalCfg, table: dict, elapsed: float, eval_problems: int) -> None:
    """The closing table: the proposals' best of ``cfg.heads`` beside random starts' on fresh problems."""
    print(f"\nposture proposals of '{robot.name}' ({elapsed:.0f} s with the data), best of {cfg.heads} on "
          f"{eval_problems} fresh problems, no iteration:")
    print(format_table(["start", "median mm", "p90 mm"],
                       [[f"proposal (best of {cfg.heads})", table["median_mm"], table["p90_mm"]],
                        [f"random (best of {cfg.heads})", table["random_median_mm"], table["random_p90_mm"]]],
                       floatfmt=".3g"))


def prepare_train_posture(cfg: Mapping[str, Any] | TrainPostureJobCfg, run_dir: str | Path
                          ) -> tuple[TrainPostureJobCfg, RobotCfg]:
    """Every check of the job before any work, writing nothing: the settings, the robot config,
    the export path and, with ``resume``, the training state in ``run_dir``."""
    job = build(TrainPostureJobCfg, cfg)
    robot_cfg = robot_cfg_from_setting(job.robot)
    if robot_cfg is None:
        raise ConfigError("robot: give robot=NAME (configs/robot/) or robot=PATH (a robot YAML) to train its "
                          "posture proposals")
    robot = Robot(robot_cfg)
    if robot.n_fingers < robot_kind(robot).min_fingers:
        raise ConfigError(f"robot '{robot_cfg.name}' needs at least {robot_kind(robot).min_fingers} fingers "
                          f"for posture proposals")
    if robot.shared.names:
        raise ConfigError(f"robot '{robot_cfg.name}': its fingers share joints ({', '.join(robot.shared.names)}); "
                          f"posture proposals do not propose them yet (its trials start at random)")
    target = export_target(job, robot_cfg)
    if target is not None:
        check_output_path(str(target), "export", ConfigError)
    state_path = Path(run_dir) / "state.pt"
    if job.resume and os.path.lexists(state_path) and not state_path.is_file():
        raise CheckpointError(f"{state_path}: cannot resume, not a regular file")
    if job.resume and state_path.is_file():
        _load_state(state_path, robot, job.posture, job.seed)
    finger_ik_of(robot)  # the FCNN places the fingers of the training data: refuse now when it is missing
    return job, robot_cfg


def export_target(job: TrainPostureJobCfg, robot_cfg: RobotCfg) -> Path | None:
    """``export=PATH``; ``export=true`` (the default) the robot's checkpoint, which the solver reads; None."""
    if job.export is False:
        return None
    return posture_checkpoint(Robot(robot_cfg)) if job.export is True else Path(job.export)


def train_posture_job(cfg: Mapping[str, Any] | TrainPostureJobCfg, run_dir: str | Path
                      ) -> tuple[PostureProposal, dict]:
    """The job behind ``scripts/train_posture.py``; ``cfg`` is the composed Hydra config as a dict."""
    job, robot_cfg = prepare_train_posture(cfg, run_dir)
    torch.set_num_threads(job.threads)
    print(f"torch.get_num_threads() = {torch.get_num_threads()}")
    robot = Robot(robot_cfg)
    return train_posture(robot, finger_ik_of(robot), job.posture, run_dir, seed=job.seed, resume=job.resume,
                         export=export_target(job, robot_cfg) or False, checkpoint_every=job.checkpoint_every,
                         progress=job.progress, eval_problems=job.eval_problems)
