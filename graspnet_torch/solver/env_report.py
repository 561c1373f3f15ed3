"""The environment contract's report part: the float64 report of trials, the exact collision
check that confirms a grasp, and the robot-kind knowledge needed without an environment (whether
a problem can be attempted, how a trial is described, what a picture marks) (:class:`ReportPart`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.scene import has_environment
from graspnet_torch.solver.contact import POINT_RULE, ContactRule
from graspnet_torch.solver.evaluation import Evaluation, Report
from graspnet_torch.solver.postures import trial_posture

if TYPE_CHECKING:
    from graspnet_torch.robot.robot import Robot
    from graspnet_torch.solver.config import SolverCfg
    from graspnet_torch.solver.result import TrialResult
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ReportPart"]


class ReportPart(ABC):
    """The report of trials and what a kind knows before any environment exists."""

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
            rule, posture = self._rule_of(int(pid[k])), trial_posture(self.robot, trial)
            scene = rule.scene(self.robot, problems[k])
            clear[k] = scene.check(posture).count == 0  # the pads' cone is in the model's error (pad_term.py)
        return clear

    def _rule_of(self, problem: int) -> ContactRule:
        """The contact rule of the environment's problem ``problem`` (its index in the batch):
        default the point model's (:mod:`graspnet_torch.solver.contact`)."""
        return POINT_RULE

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
