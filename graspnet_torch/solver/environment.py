"""The environment contract: everything a solver (srv, paper, cmaes, dls, ``solve_many``) may ask of
a robot-and-problem pair, with one signature each.

A solver never knows which robot it drives. The configuration it searches is ``n`` numbers within
``lower``/``upper`` (a free palm: 6 pose values; an arm: its joints; a mobile manipulator: base and
arm); the environment turns configurations into an :class:`Evaluation` (E of eq. 3, per-finger
errors, the finger joints the FCNN chose, collision counts, a gripper's alignment), says what the
reinforcement's base is (eq. 14, or eq. 29 for a gripper) and when a configuration is a grasp,
polishes configurations by least squares over the *whole* configuration x (the configuration with
the contact fingers' joints; what ``solver=dls`` moves), and reports each trial in float64 with the
result fields it adds to the common core (INTERFACE.md).

Robot-kind knowledge that is needed before an environment exists (whether a problem is in reach,
how a trial is described on the command line, what a picture marks) is asked of the environment
*class* (:meth:`Environment.check`, :meth:`Environment.unreachable`, :meth:`Environment.describe`,
...). :func:`graspnet_torch.solver.environments.environment_class` maps a robot's kind to its class.
A new kind of robot is a new environment, never an edit of a solver.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.collision.scene import has_environment
from graspnet_torch.rewards import r1
from graspnet_torch.solver.postures import trial_posture

if TYPE_CHECKING:
    from graspnet_torch.fcnn.ik import FingerIK
    from graspnet_torch.least_squares import LMResult
    from graspnet_torch.robot.robot import Posture, Robot
    from graspnet_torch.solver.config import SolverCfg
    from graspnet_torch.solver.result import TrialResult
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["Done", "Environment", "Evaluation", "Report"]

Done = Callable[[Tensor], Tensor]  # done(converged (B,) bool) -> (B,) bool: the rows that may stop
_PARTS = ("error", "finger_errors", "joints", "collisions", "alignment", "config")  # Evaluation's fields, in order


@dataclass
class Evaluation:
    """An environment's verdict on T configurations (leading dimension T everywhere).

    Attributes:
        error: (T,) metres: E of eq. 3, the sum of the fingertip errors.
        finger_errors: (T, F) per contact finger, or None.
        joints: (T, F, j) finger joints chosen for each contact finger, or None.
        collisions: (T,) collision count, or None when the environment has no collision component.
        alignment: (T,) a gripper's |n_gripper . n_object| (eq. 24), or None; then ``error`` is d
            (eq. 26) and the reinforcement's base is (R1 + R2) / 2 (eq. 29).
        config: (T, n) the configuration that was evaluated: the proposal itself, or where the
            environment settled it (a gripper's settling steps). :meth:`Environment.evaluate` always
            sets it; evaluations built otherwise (a polish, a report) may leave it None.
    """

    error: Tensor
    finger_errors: Tensor | None = None
    joints: Tensor | None = None
    collisions: Tensor | None = None
    alignment: Tensor | None = None
    config: Tensor | None = None

    def tensors(self) -> dict[str, Tensor]:
        """The parts that are present, by name."""
        parts = ((name, getattr(self, name)) for name in _PARTS)
        return {name: value for name, value in parts if value is not None}

    def where(self, mask: Tensor, other: Evaluation) -> Evaluation:
        """Per trial: this evaluation where ``mask`` (T,) is true, else ``other``."""
        out = {}
        for name, mine in self.tensors().items():
            theirs = getattr(other, name)  # a part only one side has (a polished row's config) is dropped
            out[name] = None if theirs is None else torch.where(mask.view(-1, *([1] * (mine.dim() - 1))), mine, theirs)
        return replace(self, **out)

    def put(self, trials: Tensor, part: Evaluation, config: Tensor) -> Evaluation:
        """This evaluation with rows ``trials`` (B,) replaced by ``part`` (an evaluation of B
        trials); ``config`` (T, n): the proposals, the evaluated configuration of the rows a
        part without ``config`` leaves unrefined."""
        out = {}
        for name, theirs in part.tensors().items():
            mine = getattr(self, name)
            base = (config if name == "config" else None) if mine is None else mine
            out[name] = base.index_copy(0, trials, theirs)
        if part.config is None:
            out["config"] = None
        return replace(self, **out)

    def clone(self) -> Evaluation:
        return replace(self, **{k: v.clone() for k, v in self.tensors().items()})


@dataclass
class Report:
    """The float64 report of T trials (:meth:`Environment.report`).

    Attributes:
        fields: per trial, the result fields the environment adds to the common core (INTERFACE.md:
            the palm pose, finger joints and fingertip errors; arm joints; a gripper's d, alignment
            and points).
        evaluation: the float64 evaluation of the reported configurations without collisions (the
            caller adds the FCL counts): what the reinforcement and ``grasped`` are recomputed from.
        error_mm: (T,) the error each trial is ranked by (E of eq. 3, or a gripper's d), millimetres.
        landed: (T,) every contact within ``solver.tolerance_mm`` (a gripper: d within it, aligned):
            the grasp but for collisions.
    """

    fields: list[dict]
    evaluation: Evaluation
    error_mm: list[float]
    landed: list[bool]

    def split(self, runs: int) -> list[Report]:
        """The reports of consecutive groups of ``runs`` trials (a batch of problems: one per
        problem, in order)."""
        ev = {k: v.split(runs) for k, v in self.evaluation.tensors().items()}
        return [Report(self.fields[a: a + runs], Evaluation(**{k: v[p] for k, v in ev.items()}),
                       self.error_mm[a: a + runs], self.landed[a: a + runs])
                for p, a in enumerate(range(0, len(self.fields), runs))]


class Environment(ABC):
    """What every solver may call. Settings reach an environment when it is built.

    Attributes:
        robot: the robot; problems: the problems (one, or a batch's), in the environment's frame;
            world_problems: the same as given (the world: what :meth:`report` answers in).
        n: size of the searched configuration.
        lower, upper: (n,) bounds, or (T, n) per trial for a batch of problems.
        problem_index: (T,) each trial's problem in a batch of problems (trial t on problem
            t // runs), or None (one problem).
        subsets: ``evaluate(config[idx], idx)`` allowed: once most trials have stopped, the loop
            evaluates the others only.
        polishes: the environment has an in-loop polish (:meth:`polish`).
        counts_collisions: its evaluations count collisions (the reward shapes them and the
            problem has something to collide with).
        error_key: the result field (JSON key) of the error a trial is ranked by.
        shared_slots: how many of the configuration's last columns are joints several fingers
            share (a free hand's; 0: the robot holds them, or has none).
    """

    error_key: ClassVar[str] = "total_error_mm"
    shared_slots: int = 0
    robot: Robot
    problems: list[GraspProblem]
    world_problems: list[GraspProblem]
    n: int
    lower: Tensor
    upper: Tensor
    problem_index: Tensor | None = None
    subsets: bool = False
    polishes: bool = False
    counts_collisions: bool = False

    # -- the search ---------------------------------------------------------------------------

    @abstractmethod
    def evaluate(self, config: Tensor, trials: Tensor | None = None) -> Evaluation:
        """(B, n) configurations of the trials ``trials`` (None: all T, in order) -> their
        evaluation, with ``config`` the configuration evaluated (the proposal, or where the
        environment settled it)."""

    def reward_base(self, evaluation: Evaluation, a: float) -> Tensor:
        """(T,) the reinforcement before collision shaping: R_1 = 1 - tanh(a E) (eq. 14)."""
        return r1(evaluation.error, a)

    def grasped(self, evaluation: Evaluation, tolerance: float) -> Tensor:
        """(T,) whether each configuration is a grasp in the model: every contact finger within
        ``tolerance`` metres of its contact and no collision where they are counted."""
        far = evaluation.finger_errors.amax(-1) if evaluation.finger_errors is not None else evaluation.error
        ok = far < tolerance
        if evaluation.collisions is not None:
            ok = ok & (evaluation.collisions == 0)
        return ok

    @abstractmethod
    def finish(self, config: Tensor, evaluation: Evaluation, done: Done | None = None) -> tuple[Tensor, Evaluation]:
        """After the search: the reported configurations (T, n) refined (the fingers' joints; the
        whole polish; a gripper's polish), never worse. ``done``: the rows that may stop."""

    def polish(self, config: Tensor, evaluation: Evaluation, trials: Tensor, done: Done | None = None
               ) -> tuple[Tensor, Evaluation]:
        """Inside the loop (when :attr:`polishes`): polish the configurations (B, n) of the trials
        ``trials`` (B,), never worse."""
        raise NotImplementedError(f"{type(self).__name__} has no in-loop polish")

    @classmethod
    def around(cls, robot: Robot, problem: GraspProblem, posture: Posture, solver: SolverCfg, ik: FingerIK | None,
               dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", collisions: bool = False
               ) -> Environment:
        """The environment of one problem for a warm start from ``posture``: where the
        configuration is searched in a frame (a free palm), that frame at the posture; otherwise
        the usual environment."""
        return cls(robot, problem, solver, ik, dtype, device, collisions)

    def proposal_input(self) -> tuple[Tensor, Tensor]:
        """What a posture proposal model (:mod:`graspnet_torch.proposal`) sees: each row's
        targets in its proposal frame (R, S, 3) and their mask (R, S), R = 1 for one problem or
        T (one row per trial) for a batch. The hand, arm and gripper environments give it."""
        raise NotImplementedError(f"{type(self).__name__} gives no input to a posture proposal model")

    def proposal_configs(self, configs: Tensor, rows: Tensor) -> Tensor:
        """A proposal model's configurations (B, K, n) for the rows ``rows`` (B,) of
        :meth:`proposal_input` -> this environment's search variables (B, K, n). Default: the
        same (the model answers in them)."""
        return configs

    # -- the whole configuration x: what solver=dls and the polishes move ------------------------

    @abstractmethod
    def random_whole(self, trials: int, gen: torch.Generator) -> Tensor:
        """x (T, m) uniform within the bounds (and joint limits), float64 on the CPU."""

    @abstractmethod
    def whole_of(self, posture: Posture) -> Tensor:
        """x (1, m) of a posture of the robot (a previous result's: a warm start) in this
        environment's search space, within the bounds and joint limits, float64 on the CPU."""

    @abstractmethod
    def local_solve(self, x: Tensor, iterations: int, tol: float = 0.0, done: Done | None = None,
                    trace: list[Tensor] | None = None, rows: Tensor | None = None) -> LMResult:
        """Levenberg-Marquardt on x (B, m) of the trials ``rows`` (None: all, in order), within
        bounds, never into a collision the proxy sees; a row stops below ``tol`` or when ``done``
        says so; ``trace`` receives the error (B,) after every step."""

    def centre(self, x: Tensor, weight: float, iterations: int) -> Tensor:
        """x (B, m) moved, the contacts held, toward the middle of the joint ranges where the
        robot has joints to spare (a sequence's posture away from its limits), with a prior of
        ``weight`` per joint range faded out over steps of ``iterations``. Default: x as it is
        (a gripper has none to spare)."""
        return x

    @abstractmethod
    def whole_result(self, solved: LMResult, like: Tensor, rows: Tensor | None = None
                     ) -> tuple[Tensor, Evaluation]:
        """The configurations (B, n) and evaluation of solved x, in the dtype and device of ``like``."""

    # -- the result ------------------------------------------------------------------------------

    @abstractmethod
    def report(self, config: Tensor, evaluation: Evaluation, rows: Tensor | None = None) -> Report:
        """The reported configurations (B, n) of the trials ``rows`` (B,) (None: all T, in order),
        recomputed in float64: clamped to the exact bounds, the errors by forward kinematics
        against the problem (INTERFACE.md)."""

    def confirm(self, config: Tensor, evaluation: Evaluation, rows: Tensor) -> Tensor:
        """(B,) which of the trials ``rows`` (B,), whose configurations (of ``config`` (T, n),
        ``evaluation``: every trial's) are grasps in the model, the exact collision check (FCL, as
        the result counts collisions) finds clear: the loop stops a trial only there, for the
        collision proxy can miss a link inside the object. All True where the problem has nothing
        to collide with."""

        rows = rows.cpu()
        pid = torch.zeros_like(rows) if self.problem_index is None else self.problem_index.cpu()[rows]
        problems = [self.world_problems[int(k)] for k in pid]
        exact = torch.tensor([has_environment(self.robot, p) for p in problems], dtype=torch.bool)
        clear = torch.ones(rows.shape[0], dtype=torch.bool)
        if not bool(exact.any()):
            return clear
        at = exact.nonzero().squeeze(1)
        part = Evaluation(**{k: v[rows[at].to(v.device)] for k, v in evaluation.tensors().items()})
        report = self.report(config[rows[at].to(config.device)], part, rows[at])
        for k, trial in zip(at.tolist(), report.fields, strict=True):
            clear[k] = scene_for(self.robot, problems[k]).check(trial_posture(self.robot, trial)).count == 0
        return clear

    # -- robot-kind knowledge needed without an environment ------------------------------------

    @classmethod
    def check(cls, robot: Robot, problem: GraspProblem, solver: SolverCfg) -> None:
        """Refuse (:class:`~graspnet_torch.errors.ProblemError`) a problem this robot cannot attempt,
        before any work (a contact beyond any reach; a gripper's approach outside its limits)."""
        return None

    @classmethod
    def unreachable(cls, robot: Robot, problem: GraspProblem) -> list[str]:
        """The contacts no configuration of the search space reaches (by name), for a failure's reason."""
        return []

    @staticmethod
    @abstractmethod
    def describe(trial: TrialResult) -> str:
        """A trial's errors in a few words (``3.5 mm from its contacts (thumb 3 mm)``)."""

    @staticmethod
    @abstractmethod
    def summary(trial: TrialResult, fingers: Sequence[str]) -> str:
        """A trial's errors on one line (``total error 0.012 mm (thumb 0.004, index 0.008)``)."""

    @staticmethod
    @abstractmethod
    def columns(trial: TrialResult, fingers: Sequence[str]) -> dict[str, float]:
        """The trial's error columns of the command line's table (headers -> values)."""

    @staticmethod
    def marks(problem: GraspProblem, trial: TrialResult) -> np.ndarray:
        """(k, 3) points a picture marks (world, metres): the contacts."""
        return problem.contacts_world()
