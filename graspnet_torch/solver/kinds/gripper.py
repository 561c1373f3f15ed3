"""The ``gripper`` kind: a body chain with two marked gripper points and no fingers (the MANUS
assistive arm on its mobile base)."""

from __future__ import annotations

from graspnet_torch.robot.heads import BodyChain
from graspnet_torch.robot.kinds import ProblemSchema, RobotKind, register_kind
from graspnet_torch.solver.gripper import GripperEnvironment
from graspnet_torch.tasks.random import random_posed_gripper

__all__ = ["GRIPPER"]

GRIPPER = register_kind(RobotKind(
    "gripper", "a body chain with two marked gripper points (MANUS): its joints put them on the object's two points",
    ProblemSchema("points", None, None, ("approach", "start")), BodyChain, GripperEnvironment, random_posed_gripper))
