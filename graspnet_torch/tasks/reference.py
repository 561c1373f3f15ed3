"""A problem's reference posture (its file's ``reference``) as a :class:`Posture` of its robot."""

from __future__ import annotations

import torch

from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.transforms import rt_to_pose
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
    if robot.has_body:
        unknown = sorted(set(ref.arm_joints or {}) - set(robot.body_joint_names))
        if unknown:
            raise ProblemError(f"{problem.source}: reference.arm_joints: unknown joint(s) {', '.join(unknown[:5])} "
                               f"of robot '{robot.name}'")
        body = home.body.clone()
        for k, name in enumerate(robot.body_joint_names):
            if ref.arm_joints and name in ref.arm_joints:
                body[k] = ref.arm_joints[name]
        return Posture(palm_pose=rt_to_pose(*robot.palm_frame(body)), fingers=q, body=body)
    return Posture(palm_pose=torch.as_tensor(ref.palm_pose, dtype=torch.float64), fingers=q, body=home.body)
