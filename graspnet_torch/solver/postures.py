"""The posture of a reported trial: a result's degrees and joint names -> a :class:`Posture`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import torch

from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver.result import TrialResult

__all__ = ["trial_posture"]


def trial_posture(robot: Robot, trial: TrialResult | Mapping[str, Any]) -> Posture:
    """The :class:`~graspnet_torch.robot.Posture` of a reported trial (its degrees -> radians):
    palm pose, every finger's joints (and the joints fingers share, as listed) and, for robots
    with a body, the body joints by name."""
    get = trial.get if isinstance(trial, Mapping) else lambda k: getattr(trial, k)
    d = math.pi / 180
    palm = get("palm_pose")
    pose = torch.tensor(palm[:3] + [a * d for a in palm[3:]], dtype=torch.float64)
    joints = get("joints") or {}
    q = robot.finger_joints_from_file(joints)
    body = robot.body_joints_from_file(get("arm_joints") or {})
    shared = robot.shared_joints_of(robot.finger_values_from_file(joints)) if robot.shared.n else None
    return Posture(palm_pose=pose, fingers=q, body=body, shared=shared)
