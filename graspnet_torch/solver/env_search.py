"""The environment contract's search part: what the searches (srv, paper, cmaes) ask of a
robot-and-problem pair while they search (:class:`SearchPart`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from graspnet_torch.rewards import r1
from graspnet_torch.solver.evaluation import Done, Evaluation

if TYPE_CHECKING:
    from graspnet_torch.fcnn.ik import FingerIK
    from graspnet_torch.robot.robot import Posture, Robot
    from graspnet_torch.solver.config import SolverCfg
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["SearchPart"]


class SearchPart(ABC):
    """Configurations -> evaluations, the reinforcement's base, when a configuration is a grasp,
    the refinement after (and during) the search, warm starts and a proposal model's view."""

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
        ``tolerance`` metres of its contact (the surface model: its pad, within the cone) and no
        collision where they are counted."""
        errors = evaluation.grasp_errors()
        far = errors.amax(-1) if errors is not None else evaluation.error
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
               ) -> SearchPart:
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

