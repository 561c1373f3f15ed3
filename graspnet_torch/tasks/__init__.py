"""Grasp problems: objects, contact sets, problem files, shipped tasks and random problems."""

from graspnet_torch.tasks.problem import Contact, GraspProblem, ReferencePosture, Shape, available_tasks
from graspnet_torch.tasks.random import (
    random_arm_problem,
    random_gripper_problems,
    random_hand_problem,
    random_reachable_problem,
    random_sequence,
)

__all__ = ["Contact", "GraspProblem", "ReferencePosture", "Shape", "available_tasks", "random_arm_problem",
           "random_gripper_problems", "random_hand_problem", "random_reachable_problem", "random_sequence"]
