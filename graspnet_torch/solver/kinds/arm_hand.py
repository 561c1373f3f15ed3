"""The ``arm_hand`` kind: fingers on a body chain (a 7-DOF arm carrying the hand)."""

from __future__ import annotations

from graspnet_torch.robot.heads import BodyChain
from graspnet_torch.robot.kinds import ProblemSchema, RobotKind, register_kind
from graspnet_torch.solver.arm import ArmHandEnvironment
from graspnet_torch.tasks.random import arm_walk_space, random_arm_problem, random_posed_fingers

__all__ = ["ARM_HAND"]

ARM_HAND = register_kind(RobotKind(
    "arm_hand", "fingers on a body chain: the arm's joints carry the palm, the FCNN places the fingers",
    ProblemSchema("contacts", "bounds", "arm_joints", ("start",)), BodyChain, ArmHandEnvironment,
    random_posed_fingers, random_problem=random_arm_problem, walk_space=arm_walk_space, min_fingers=2))
