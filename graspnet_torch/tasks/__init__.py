"""Grasp problems: objects, contact sets, problem files and shipped tasks."""

from graspnet_torch.tasks.problem import Contact, GraspProblem, ReferencePosture, Shape, available_tasks
from graspnet_torch.tasks.random import random_reachable_problem

__all__ = ["Contact", "GraspProblem", "ReferencePosture", "Shape", "available_tasks", "random_reachable_problem"]
