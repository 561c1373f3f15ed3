"""Which environment solves a robot: :data:`ENVIRONMENTS` names the class of each robot kind."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver.arm import ArmHandEnvironment
from graspnet_torch.solver.config import RewardCfg, SolverCfg
from graspnet_torch.solver.environment import Environment
from graspnet_torch.solver.gripper import GripperEnvironment
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ENVIRONMENTS", "build_environment", "environment_class"]

ENVIRONMENTS: dict[str, type[Environment]] = {
    "hand": HandEnvironment,  # a free palm with fingers: the palm pose, the FCNN places the fingers
    "arm_hand": ArmHandEnvironment,  # fingers on an arm: its joints, the FCNN places the fingers
    "gripper": GripperEnvironment,  # a body chain with two gripper points (MANUS)
}
"""Robot kind -> the environment class that solves it."""

def environment_class(robot: Robot) -> type[Environment]:
    """The environment class of a robot's kind (:data:`ENVIRONMENTS`)."""
    return ENVIRONMENTS[robot.kind]


def build_environment(robot: Robot, problem: GraspProblem | Sequence[GraspProblem], finger_ik: FingerIK | None,
                      solver: SolverCfg, dtype: torch.dtype = torch.float32, device: str | torch.device = "cpu",
                      reward: RewardCfg | None = None, runs: int = 1, around: Posture | None = None) -> Environment:
    """The environment of a robot and a problem (or a batch of problems, ``runs`` trials each),
    built with the solver's settings. It counts collisions (the torch proxy of
    :mod:`graspnet_torch.collision.proxy`) when the reward uses them (R2-R4) and the problem has an
    object or obstacles. ``around``: a warm start's posture (one problem;
    :meth:`~graspnet_torch.solver.environment.Environment.around`)."""
    collisions = reward is not None and reward.kind != "r1"
    if around is not None:
        if not isinstance(problem, GraspProblem):
            raise ValueError("build_environment: a warm start (around=) is for one problem")
        return environment_class(robot).around(robot, problem, around, solver, finger_ik, dtype, device, collisions)
    return environment_class(robot)(robot, problem, solver, finger_ik, dtype, device, collisions, runs)
