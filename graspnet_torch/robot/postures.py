"""Postures of results and problems: a reported trial, or a problem's reference, as a :class:`Posture`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import torch

from graspnet_torch.robot.robot import Posture, Robot

if TYPE_CHECKING:
    from graspnet_torch.solver.result import TrialResult
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["build_home_posture", "reference_posture", "trial_posture"]


def trial_posture(robot: Robot, trial: TrialResult | Mapping[str, Any]) -> Posture:
    """The :class:`~graspnet_torch.robot.Posture` of a reported trial (its degrees -> radians):
    palm pose, every finger's joints (and the joints fingers share, as listed) and, for robots
    with a body, the body joints by name."""
    get = trial.get if isinstance(trial, Mapping) else lambda k: getattr(trial, k)
    d = math.pi / 180
    palm = get("palm_pose")
    pose = torch.tensor(palm[:3] + [a * d for a in palm[3:]], dtype=torch.float64)
    joints = get("joints") or {}
    q = robot.finger_joints_from_file(joints) if robot.n_fingers else torch.zeros(0, 0, dtype=torch.float64)
    body = robot.body_joints_from_file(get("arm_joints")) if robot.has_body else torch.zeros(0, dtype=torch.float64)
    shared = robot.shared_joints_of(robot.finger_values_from_file(joints)) if robot.shared.n else None
    return Posture(palm_pose=pose, fingers=q, body=body, shared=shared)


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
            from graspnet_torch.errors import ProblemError

            raise ProblemError(f"{problem.source}: reference.arm_joints: unknown joint(s) {', '.join(unknown[:5])} "
                               f"of robot '{robot.name}'")
        body = home.body.clone()
        for k, name in enumerate(robot.body_joint_names):
            if ref.arm_joints and name in ref.arm_joints:
                body[k] = ref.arm_joints[name]
        from graspnet_torch.robot.transforms import rt_to_pose

        return Posture(palm_pose=rt_to_pose(*robot.palm_frame(body)), fingers=q, body=body)
    return Posture(palm_pose=torch.as_tensor(ref.palm_pose, dtype=torch.float64), fingers=q, body=home.body)


def build_home_posture(robot: Robot, dtype: torch.dtype = torch.float64) -> Posture:
    """The config's ``home`` joints (degrees/metres in the file), clipped to the joint limits; a
    free hand's palm at the world origin (:meth:`Robot.home_posture`, which keeps one per dtype)."""
    from graspnet_torch.errors import ConfigError

    home = robot.cfg.home
    unknown = sorted(set(home) - set(robot.urdf.movable_joint_names))
    if unknown:
        raise ConfigError(f"{robot.cfg.source}: home names unknown joint(s) {', '.join(unknown)}")

    def values(spec_names, lower, upper, types):
        out = []
        for name, lo, hi, kind in zip(spec_names, lower, upper, types, strict=True):
            v = home.get(name, 0.0)
            out.append(min(max(math.radians(v) if kind == "revolute" else v, lo), hi))
        return out

    finger_q = torch.zeros(robot.n_fingers, robot.joints_per_finger, dtype=dtype)
    for k, f in enumerate(robot.fingers.values()):
        finger_q[k, : f.n_joints] = torch.tensor(values(f.joint_names, f.chain.lower, f.chain.upper,
                                                        f.chain.joint_types), dtype=dtype)
    if robot.body is not None:
        from graspnet_torch.robot.transforms import rt_to_pose

        body_q = torch.tensor(values(robot.body.joint_names, robot.body.lower, robot.body.upper,
                                     robot.body.joint_types), dtype=dtype)
        palm = rt_to_pose(*robot.palm_frame(body_q))
    else:
        body_q = torch.zeros(0, dtype=dtype)
        palm = torch.zeros(6, dtype=dtype)
    return Posture(palm_pose=palm, fingers=finger_q, body=body_q)
