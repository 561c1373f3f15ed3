"""Typed settings of every command-line job, one dataclass per script (its Hydra primary config).

Each field has a type and a range (:func:`graspnet_torch.settings.setting`); groups are the
component configs (``solver`` -> :class:`SolverCfg`, ``fcnn`` -> :class:`FCNNTrainCfg`, ...); the
``task`` and ``robot`` groups are validated by their own parsers (problem files, robot configs).
The command line checks overrides against these before Hydra composes anything
(:mod:`graspnet_torch.jobs.cli`), and each job checks its whole composed config again with
:func:`graspnet_torch.settings.build`, so a setting from a YAML file is held to the same rules.

Resources are checked before work as well: :func:`check_device` (the device exists here) and
:func:`check_solve_memory` (trials x iterations x history fit in memory).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from graspnet_torch.errors import ConfigError
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.motion.config import ReachCfg
from graspnet_torch.physics.config import PhysicsCfg
from graspnet_torch.proposal.model import ProposalCfg
from graspnet_torch.settings import DefaultsFile, Free, clip, setting
from graspnet_torch.solver.config import DEFAULT_TRIALS, NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.srv.network import SRVNetCfg

__all__ = ["DEFAULTS_FILES", "InspectRobotsJobCfg", "ReferencePostureJobCfg", "SolveGraspJobCfg", "TrainFCNNJobCfg",
           "TrainPostureJobCfg", "available_memory", "check_device", "check_solve_memory", "check_train_memory",
           "estimate_solve_memory", "estimate_train_memory"]

MAX_SEED = 2**63 - 1


@dataclass(frozen=True)
class SolveGraspJobCfg:
    """``scripts/solve_grasp.py`` (configs/solve_grasp.yaml)."""

    task: Free = None  # a task name or the task config Hydra composed from configs/task/
    robot: Free = None  # optional; must match the problem's robot
    srv: SRVNetCfg = setting(factory=SRVNetCfg)
    reward: RewardCfg = setting(factory=RewardCfg)
    solver: SolverCfg = setting(factory=SolverCfg)
    noise: NoiseCfg = setting(factory=NoiseCfg)
    problem: str | None = None
    out: str | None = None
    trials: int = setting(DEFAULT_TRIALS, lo=1, hi=1_000_000_000)  # gt.solve's default; within memory too
    seed: int = setting(0, lo=0, hi=MAX_SEED)
    max_iterations: int | None = setting(None, lo=1, hi=10_000_000)  # an override of solver.max_iterations (None: not)
    device: str = "cpu"
    threads: int = setting(1, lo=1, hi=1024)
    tensorboard: bool = True
    log_every: int = setting(10, lo=1, hi=10_000_000)
    pictures: bool = True
    allow_outside_paths: bool = False
    batch: int = setting(1000, lo=1, hi=1_000_000)  # problem=DIR / .jsonl: problems per vectorised search
    sequence: bool = False  # problem=DIR / .jsonl: frames in order, each warm-started from the last (gt.Solver.track)
    reach: ReachCfg = setting(factory=ReachCfg)  # reach=true: the motion to the grasp (reach.timeout_s=..., ...)
    # verify=physics: report the first successful trial (best first) that holds its object in MuJoCo, with
    # reach=true also one with a motion found (graspnet_torch.jobs.verify)
    verify: str = setting("none", choices=("none", "physics"))
    verify_trials: int = setting(20, lo=1, hi=1_000_000)  # verify=physics / reach=true: most trials checked
    physics: PhysicsCfg = setting(factory=PhysicsCfg)  # verify=physics: the check's protocol (physics.friction=...)


@dataclass(frozen=True)
class TrainFCNNJobCfg:
    """``scripts/train_fcnn.py`` (configs/train_fcnn.yaml)."""

    robot: Free = None
    fcnn: FCNNTrainCfg = setting(factory=FCNNTrainCfg)
    seed: int = setting(0, lo=0, hi=MAX_SEED)
    fingers: list[str] | None = None
    resume: bool = False
    export: bool | str | None = None  # None: export when every finger is trained
    checkpoint_every: int = setting(25, lo=1, hi=10_000_000)
    progress: bool = True
    threads: int = setting(1, lo=1, hi=1024)
    eval_targets: int = setting(10_000, lo=1, hi=1_000_000)
    allow_outside_paths: bool = False  # the robot's URDF and meshes anywhere


@dataclass(frozen=True)
class TrainPostureJobCfg:
    """``scripts/train_posture.py`` (configs/train_posture.yaml)."""

    robot: Free = None
    posture: ProposalCfg = setting(factory=ProposalCfg)
    seed: int = setting(0, lo=0, hi=2**31 - 1)
    resume: bool = False
    export: bool | str = True  # true: the robot's checkpoint (what the solver reads); false; or a path
    checkpoint_every: int = setting(1000, lo=1, hi=10_000_000)
    progress: bool = True
    threads: int = setting(1, lo=1, hi=1024)
    eval_problems: int = setting(200, lo=1, hi=1_000_000)


@dataclass(frozen=True)
class InspectRobotsJobCfg:
    """``scripts/inspect_robots.py`` (configs/inspect_robots.yaml)."""

    robots: list[str] = setting(factory=lambda: ["hand", "arm_hand", "manus"])
    out_dir: str | None = None  # None: the run folder


@dataclass(frozen=True)
class ReferencePostureJobCfg:
    """``scripts/reference_posture.py`` (configs/reference_posture.yaml)."""

    task: Free = None
    problem: str | None = None
    restarts: int = setting(24, lo=1, hi=1000)
    seed: int = setting(0, lo=0, hi=MAX_SEED)
    allow_outside_paths: bool = False


_JOB = ("defaults", "hydra")  # a job file's keys that are Hydra's
# The YAML files under configs/ that list these settings' defaults: their values are written from the
# dataclasses (scripts/sync_defaults.py, `make sync-defaults`; tests/test_defaults_files.py fails when
# one differs), never by hand. The experiments' files: graspnet_torch.experiments.DEFAULTS_FILES.
DEFAULTS_FILES = (
    DefaultsFile("solver/srv.yaml", SolverCfg, unset=True),
    DefaultsFile("srv/default.yaml", SRVNetCfg, unset=True),
    DefaultsFile("reward/default.yaml", RewardCfg, unset=True),
    DefaultsFile("noise/none.yaml", NoiseCfg),
    DefaultsFile("posture/default.yaml", ProposalCfg),
    # epochs: 300 on the command line (the shipped checkpoints') against FCNNTrainCfg's 400: kept as it is
    DefaultsFile("fcnn/default.yaml", FCNNTrainCfg),
    DefaultsFile("solve_grasp.yaml", SolveGraspJobCfg, skip=_JOB, complete=False),
    DefaultsFile("train_fcnn.yaml", TrainFCNNJobCfg, skip=_JOB, complete=False),
    DefaultsFile("train_posture.yaml", TrainPostureJobCfg, skip=_JOB, complete=False),
    DefaultsFile("inspect_robots.yaml", InspectRobotsJobCfg, skip=_JOB, complete=False),
    DefaultsFile("reference_posture.yaml", ReferencePostureJobCfg, skip=_JOB, complete=False),
)


def check_device(device: str):
    """``device`` as a ``torch.device`` that exists on this machine, or a :class:`ConfigError`."""
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ConfigError(f"device={clip(device, 40)}: not a device (expected cpu, cuda or cuda:N)") from None
    if dev.type == "cpu":
        return dev
    if dev.type != "cuda":
        raise ConfigError(f"device={clip(device, 40)}: not supported (expected cpu, cuda or cuda:N)")
    if not torch.cuda.is_available():
        raise ConfigError(f"device={clip(device, 40)}: CUDA is not available on this machine; use device=cpu")
    if dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ConfigError(f"device={clip(device, 40)}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    return dev


# Bytes per trial, measured on the CPU (peak RSS of gt.solve on block5, 5 fingers, float32, at
# T = 20k-50k): the loop's working set is ~4.8 kB per finger; the history (reinforcement, observed,
# expected and sigma per unit, total, per-finger errors) ~470 B per iteration with 5 fingers
# (80 B of data, the rest the stacking into curves and allocator fragmentation).
WORK_BYTES_PER_FINGER = 5_000
HISTORY_FACTOR = 6  # history bytes = HISTORY_FACTOR x itemsize x (3 + 2 n + F) per iteration
BASE_BYTES = 768 << 20  # torch, the robot, the FCNN (measured: 300-530 MB)


def estimate_solve_memory(trials: int, iterations: int, fingers: int, n: int = 6, history: bool = True,
                          itemsize: int = 4, hidden: tuple[int, int] = (20, 20), postures: bool = False) -> int:
    """Peak bytes of a solve of ``trials`` x ``iterations`` (an upper estimate; see the constants);
    each trial's network (weights, their updates and the layers' activations) counts 4 times."""
    h1, h2 = hidden
    per_trial = WORK_BYTES_PER_FINGER * fingers * itemsize // 4
    per_trial += 4 * itemsize * (2 * n * h1 + h1 * h2 + h2 * n + h1 + h2 + n)
    if history:
        per_trial += iterations * HISTORY_FACTOR * itemsize * (3 + 2 * n + fingers)
        if postures:  # each iteration's configuration and finger joints (4 per finger)
            per_trial += iterations * itemsize * (n + 4 * fingers)
    return BASE_BYTES + trials * per_trial


def estimate_train_memory(cfg: FCNNTrainCfg, eval_targets: int, n: int = 4) -> int:
    """Peak bytes of training one finger (an upper estimate, float32): the experts with their
    gradients and Adam moments (x 4), the activations of the largest batch through every expert
    (validation, evaluation, a training step: x 3), and the reaching motions of step 4 (every
    unsolved target's random restarts, with their paths)."""
    E, H = cfg.experts.max_experts, cfg.experts.hidden
    params = E * (3 * H + H * H + H * n + 2 * H + n)
    batch = max(cfg.val_targets, eval_targets, cfg.batch_size)
    reach = cfg.targets_per_epoch * max(cfg.random_restarts, 1) * (64 * n + 32)
    return BASE_BYTES + 4 * (4 * params + 3 * batch * E * (2 * H + n) + reach)


def check_train_memory(cfg: FCNNTrainCfg, eval_targets: int) -> int:
    """Refuse training settings that cannot fit in memory, naming the estimate."""
    need, have = estimate_train_memory(cfg, eval_targets), available_memory()
    if need > have:
        raise ConfigError(f"these fcnn settings need about {need / 2**30:.1f} GiB of memory but {have / 2**30:.1f} GiB "
                          f"are available: use fewer experts, hidden units, targets or restarts")
    return need


def available_memory() -> int:
    """Bytes of memory available to a new allocation on this machine (Linux: MemAvailable)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")


def check_solve_memory(trials: int, iterations: int, fingers: int, history: bool, itemsize: int,
                       device=None, hidden: tuple[int, int] = (20, 20), postures: bool = False) -> int:
    """Refuse a solve that cannot fit in memory, naming the estimate; returns the estimate."""
    need = estimate_solve_memory(trials, iterations, fingers, history=history, itemsize=itemsize, hidden=hidden,
                                 postures=postures)
    if device is not None and getattr(device, "type", "cpu") == "cuda":
        import torch

        have = torch.cuda.mem_get_info(device)[0]
        where = "free on the GPU"
    else:
        have = available_memory()
        where = "available"
    if need > have:
        hist = "" if not history else "; solver.history=false drops the per-iteration curves"
        raise ConfigError(f"trials={trials} x max_iterations={iterations} needs about {need / 2**30:.1f} GiB of "
                          f"memory but {have / 2**30:.1f} GiB are {where}: use fewer trials or iterations{hist}")
    return need
