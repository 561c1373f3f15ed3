"""The ``hand`` kind: a free palm with fingers (the paper's hand)."""

from __future__ import annotations

from graspnet_torch.robot.heads import FreePalm
from graspnet_torch.robot.kinds import ProblemSchema, RobotKind, register_kind
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.tasks.random import hand_walk_space, random_hand_problem, random_posed_fingers

__all__ = ["HAND"]

HAND = register_kind(RobotKind(
    "hand", "a free palm with fingers: 6 pose values, the FCNN places the fingers",
    ProblemSchema("contacts", "palm_bounds", "palm_pose"), FreePalm, HandEnvironment, random_posed_fingers,
    random_problem=random_hand_problem, walk_space=hand_walk_space, closure=True, min_fingers=2))
