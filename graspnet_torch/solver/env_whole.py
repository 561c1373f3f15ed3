"""The environment contract's whole-configuration part: the configuration x with the contact
fingers' joints, what ``solver=dls`` and the polishes move by least squares (:class:`WholePart`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from graspnet_torch.solver.evaluation import Done, Evaluation

if TYPE_CHECKING:
    from graspnet_torch.least_squares import LMResult
    from graspnet_torch.robot.robot import Posture

__all__ = ["WholePart"]


class WholePart(ABC):
    """Random and warm-started whole configurations, their local solve on the one
    Levenberg-Marquardt, and the configurations and evaluation of a solve."""

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

