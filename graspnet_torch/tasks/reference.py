"""A problem's reference posture (its file's ``reference``) as a :class:`Posture` of its robot."""

from __future__ import annotations

import torch

from graspnet_torch.robot.heads import head_of
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["reference_posture"]


def reference_posture(robot: Robot, problem: GraspProblem) -> Posture:
    """The problem's reference posture as a :class:`~graspnet_torch.robot.Posture` (fingers not
    listed at home; an arm's joints not listed at home, its palm by forward kinematics)."""
    ref = problem.reference
    if ref is None:
        raise ValueError(f"{problem.source}: no reference posture")
    home = robot.home_posture(torch.float64)
    q = home.fingers.clone()
    for f, v in ref.joints.items():
        q[robot.finger_index(f)] = torch.as_tensor(v, dtype=torch.float64)
    head = head_of(robot).from_reference(ref.palm_pose, ref.arm_joints, problem.source)  # palm pose or arm joints
    return head_of(robot).postures(head[None], q[None])[0]
