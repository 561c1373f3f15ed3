"""How a robot's palm is placed: the leading values of its configuration (its "head").

A free hand's palm is placed by its pose (x, y, z, rx, ry, rz: m, rad) (:class:`FreePalm`); a
robot with a body (an arm, a mobile base and an arm) by its body joints, the palm at the end of the
body chain (:class:`BodyChain`). :data:`HEADS` names each kind's head; code that plans, checks or
draws a configuration asks the robot's head (:func:`head_of`) and never branches on the robot's
kind. Every method is batched over leading dimensions unless it says otherwise.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping, Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.structure import Posture
from graspnet_torch.robot.transforms import rt_to_pose

__all__ = ["HEADS", "BodyChain", "FreePalm", "Head", "head_of", "urdf_velocity"]


def urdf_velocity(robot: Robot, joint: str) -> float:
    """A joint's speed limit (URDF ``<limit velocity>``, rad/s or m/s); refuses a joint without one."""
    limit = robot.urdf.joints[joint].limit
    v = None if limit is None else limit.velocity
    if v is None or not math.isfinite(float(v)) or float(v) <= 0:
        raise ValueError(f"{robot.cfg.urdf}: joint '{joint}' has no velocity limit (<limit velocity=...>)")
    return float(v)


class Head:
    """The values that place a robot's palm (the base class: see :class:`FreePalm`, :class:`BodyChain`).

    Attributes:
        robot: the robot.
        names: (n,) the values' names (joint names, or ``palm_x`` .. ``palm_rz``).
        revolute: (n,) which values are angles.
        lower, upper: (n,) limits (radians or metres; a free palm: unbounded).
        anchored: whether the palm is carried from a fixed base, so that a motion starts at the
            robot's start configuration (a free palm's motion starts at its approach).
    """

    anchored: bool = False

    def __init__(self, robot: Robot):
        self.robot = robot
        self.names: tuple[str, ...] = ()
        self.revolute = np.zeros(0, dtype=bool)
        self.lower = self.upper = np.zeros(0)

    @property
    def n(self) -> int:
        """How many values place the palm."""
        return len(self.names)

    def velocity(self, palm_speed: float) -> np.ndarray:
        """(n,) speed limits (m/s, rad/s); ``palm_speed``: a free palm's linear speed."""
        raise NotImplementedError

    def values(self, posture: Posture) -> Tensor:
        """A posture's head values (n,)."""
        raise NotImplementedError

    def postures(self, head: Tensor, fingers: Tensor) -> list[Posture]:
        """The postures of head values (B, n) and free finger joints (B, F, j)."""
        raise NotImplementedError

    def fingertips(self, head: Tensor, q: Tensor) -> Tensor:
        """Fingertips in the world: head (..., n), q (..., F, j) -> (..., F, 3)."""
        raise NotImplementedError

    def world_to_bases(self, points: Tensor, head: Tensor) -> Tensor:
        """World points, one per finger (..., F, 3) -> each in its finger's base frame (..., F, 3)."""
        raise NotImplementedError

    def link_frames(self, head: Tensor, q: Tensor) -> tuple[list[str], np.ndarray]:
        """The links' names and world poses (B, L, 4, 4) from head values (B, n) and fingers (B, F, j)."""
        raise NotImplementedError

    def from_reference(self, palm_pose: Sequence[float] | None, arm_joints: Mapping[str, float] | None,
                       where: str) -> Tensor:
        """The head values (n,) a problem's reference posture gives (its ``palm_pose``, m and rad;
        or its ``arm_joints`` by name, rad or m, the others at home); ``where`` names it in a
        refusal (:class:`~graspnet_torch.errors.ProblemError`)."""
        raise NotImplementedError


class FreePalm(Head):
    """A free hand: the palm pose (x, y, z in m, rx, ry, rz in rad), unbounded."""

    def __init__(self, robot: Robot):
        super().__init__(robot)
        self.names = tuple(f"palm_{a}" for a in ("x", "y", "z", "rx", "ry", "rz"))
        self.revolute = np.array([False] * 3 + [True] * 3)
        self.lower, self.upper = np.full(6, -math.inf), np.full(6, math.inf)

    def velocity(self, palm_speed: float) -> np.ndarray:
        """The palm moves at ``palm_speed`` m/s along each axis and turns at twice that in rad/s."""
        return np.array([palm_speed] * 3 + [palm_speed * 2] * 3)

    def values(self, posture: Posture) -> Tensor:
        return posture.palm_pose

    def postures(self, head: Tensor, fingers: Tensor) -> list[Posture]:
        none = torch.zeros(0, dtype=torch.float64)
        return [Posture(palm_pose=head[k], fingers=fingers[k], body=none) for k in range(head.shape[0])]

    def fingertips(self, head: Tensor, q: Tensor) -> Tensor:
        return self.robot.fingertips_world(head, q)

    def world_to_bases(self, points: Tensor, head: Tensor) -> Tensor:
        return self.robot.world_to_bases(points, head)

    def link_frames(self, head: Tensor, q: Tensor) -> tuple[list[str], np.ndarray]:
        return self.robot.link_frames_of(None, q, head)

    def from_reference(self, palm_pose: Sequence[float] | None, arm_joints: Mapping[str, float] | None,
                       where: str) -> Tensor:
        if palm_pose is None:
            raise ProblemError(f"{where}: reference.palm_pose: a free hand's reference gives its palm pose")
        return torch.as_tensor(palm_pose, dtype=torch.float64)


class BodyChain(Head):
    """A robot with a body: its body joints (URDF order; radians or metres) within their limits."""

    anchored = True

    def __init__(self, robot: Robot):
        super().__init__(robot)
        self.names = robot.body_joint_names
        self.revolute = np.array([t != "prismatic" for t in robot.body.joint_types], dtype=bool)
        self.lower, self.upper = robot.body_limits

    def velocity(self, palm_speed: float) -> np.ndarray:
        """Each body joint's URDF speed limit (``palm_speed`` is unused)."""
        return np.array([urdf_velocity(self.robot, name) for name in self.names], dtype=np.float64)

    def values(self, posture: Posture) -> Tensor:
        return posture.body

    def postures(self, head: Tensor, fingers: Tensor) -> list[Posture]:
        palm = rt_to_pose(*self.robot.palm_frame(head))
        return [Posture(palm_pose=palm[k], fingers=fingers[k], body=head[k]) for k in range(head.shape[0])]

    def fingertips(self, head: Tensor, q: Tensor) -> Tensor:
        return self.robot.fingertips_world_from_body(head, q)

    def world_to_bases(self, points: Tensor, head: Tensor) -> Tensor:
        return self.robot.world_to_bases_from_body(points, head)

    def link_frames(self, head: Tensor, q: Tensor) -> tuple[list[str], np.ndarray]:
        return self.robot.link_frames_of(head, q)

    def from_reference(self, palm_pose: Sequence[float] | None, arm_joints: Mapping[str, float] | None,
                       where: str) -> Tensor:
        unknown = sorted(set(arm_joints or {}) - set(self.names))
        if unknown:
            raise ProblemError(f"{where}: reference.arm_joints: unknown joint(s) {', '.join(unknown[:5])} "
                               f"of robot '{self.robot.name}'")
        body = self.robot.home_posture(torch.float64).body.clone()
        for k, name in enumerate(self.names):
            if arm_joints and name in arm_joints:
                body[k] = arm_joints[name]
        return body


HEADS: dict[str, type[Head]] = {"hand": FreePalm, "arm_hand": BodyChain, "gripper": BodyChain}
"""Robot kind -> its head: a free hand's palm pose, else the body chain's joints."""

_MADE: weakref.WeakKeyDictionary[Robot, Head] = weakref.WeakKeyDictionary()


def head_of(robot: Robot) -> Head:
    """How a robot's palm is placed: its kind's head (:data:`HEADS`), made once per robot."""
    head = _MADE.get(robot)
    if head is None:
        head = _MADE[robot] = HEADS[robot.kind](robot)
    return head
