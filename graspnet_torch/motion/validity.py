"""Collision checks of a robot's states and straight motions (FCL, the model of the result's
``collisions``), for the planner and for the independent re-check of a motion.

A state is a vector x of the planned variables in internal units: a robot with a body, its body
joints then its free finger joints (F, n) flattened; a free hand, its palm pose (x, y, z, rx,
ry, rz) then its fingers. A state is clear when no link collides with an obstacle, the floor or
another link and none enters the object by more than the tolerance; only where a contact
fingertip has arrived within ``touch_mm`` of its contact may that finger's distal link touch the
object, as in the reported grasp (a gripper: its jaws, once both marked points have arrived).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.robot.heads import head_of, urdf_velocity
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["MotionChecker", "StateLayout", "state_postures"]


@dataclass(frozen=True)
class StateLayout:
    """The planned variables of a robot: names, which are angles, limits and the check's step.

    Attributes:
        names: the trajectory's joint names (a free hand: ``palm_x`` .. ``palm_rz`` first; then
            every finger's free joints, by URDF name).
        revolute: (n,) which variables are angles.
        lower, upper: (n,) limits (a free hand's palm: +-inf, its angles +-pi).
        velocity: (n,) speed limits (URDF ``<limit velocity>``; a free hand's palm: ``palm_speed``).
        body: how many leading variables move the palm (body joints or the palm pose).
    """

    names: tuple[str, ...]
    revolute: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    body: int

    @classmethod
    def of(cls, robot: Robot, palm_speed: float = 0.5) -> StateLayout:
        """The robot's head values (:func:`~graspnet_torch.robot.heads.head_of`: a free palm's pose
        or the body joints), then every finger's free joints by URDF name."""
        head = head_of(robot)
        names, revolute = list(head.names), list(head.revolute)
        lower, upper, velocity = list(head.lower), list(head.upper), list(head.velocity(palm_speed))
        flo, fhi = robot.finger_limits
        for k, finger in enumerate(robot.fingers.values()):
            chain = finger.chain
            for i in range(finger.n_joints):
                name = chain.joint_names[i]
                names.append(name)
                revolute.append(chain.spec.joint_types[chain.free[i]] != "prismatic")
                lower.append(flo[k, i])
                upper.append(fhi[k, i])
                velocity.append(urdf_velocity(robot, name))
        return cls(tuple(names), np.asarray(revolute), np.asarray(lower), np.asarray(upper), np.asarray(velocity),
                   head.n)

    def steps(self, a: np.ndarray, b: np.ndarray, resolution_deg: float, resolution_mm: float) -> int:
        """How many equal steps from a to b keep every variable's step within the resolution."""
        res = np.where(self.revolute, math.radians(resolution_deg), resolution_mm / 1000.0)
        return max(1, math.ceil(float(np.max(np.abs(b - a) / res)) - 1e-9))

    def scale(self, resolution_deg: float, resolution_mm: float) -> np.ndarray:
        """(n,) the step of each variable: a state in units of it moves each by at most 1 per unit."""
        return np.where(self.revolute, math.radians(resolution_deg), resolution_mm / 1000.0)


def state_postures(robot: Robot, layout: StateLayout, states: np.ndarray) -> list[Posture]:
    """The :class:`Posture` of each state (B, n) (internal units), the palm poses of a robot with a
    body by one batched forward kinematics (:meth:`Head.postures <graspnet_torch.robot.heads.Head.postures>`)."""
    x = torch.as_tensor(np.asarray(states, dtype=np.float64))
    return head_of(robot).postures(x[:, :layout.body], _finger_joints(robot, x, layout.body))


def _finger_joints(robot: Robot, x: torch.Tensor, m: int) -> torch.Tensor:
    """States (B, n) -> every finger's free joints (B, F, j), padded: the columns after the first m."""
    q = torch.zeros(x.shape[0], robot.n_fingers, robot.joints_per_finger, dtype=torch.float64)
    q[:, torch.as_tensor(robot.finger_mask)] = x[:, m:]
    return q


class MotionChecker:
    """FCL checks of states and straight motions of one robot in one problem's scene."""

    def __init__(self, robot: Robot, problem: GraspProblem, layout: StateLayout, touch_mm: float = 40.0):
        self.robot, self.problem, self.layout, self.touch = robot, problem, layout, touch_mm / 1000.0
        self.scene = CollisionScene(robot, problem, touching=False)
        self.checks = 0
        if problem.fingers:  # contacts, one per finger
            self._rows = [robot.finger_index(f) for f in problem.fingers]
            self._targets = torch.as_tensor(np.asarray(problem.contacts_world(), dtype=np.float64))
            groups = [(f,) for f in problem.fingers]
        else:
            self._targets = torch.as_tensor(problem.points_world(), dtype=torch.float64)
            groups = [()]  # a gripper: its jaws, together
        shapes = self.scene.shapes
        self._distal = np.array([[s.link in CollisionScene.distal_links(robot, shapes, g) for s in shapes]
                                 for g in groups], dtype=np.float64)  # (k, S): each finger's touching shapes

    def arrived_fingers(self, states: np.ndarray) -> np.ndarray:
        """(B, k) whether each contact fingertip lies within ``touch_mm`` of its contact (a
        gripper: one column, both marked points, either pairing)."""
        robot, m = self.robot, self.layout.body
        x = torch.as_tensor(np.asarray(states, dtype=np.float64))
        if not self.problem.fingers:  # a gripper's two points
            points = robot.gripper_points(x[:, :m])
            d = torch.minimum((points - self._targets).norm(dim=-1).amax(-1),
                              (points - self._targets.flip(0)).norm(dim=-1).amax(-1))
            return (d <= self.touch).numpy()[:, None]
        q = _finger_joints(robot, x, m)
        tips = head_of(robot).fingertips(x[:, :m], q)
        return ((tips[:, self._rows] - self._targets).norm(dim=-1) <= self.touch).numpy()

    def arrived(self, states: np.ndarray) -> np.ndarray:
        """(B,) whether every contact fingertip has arrived (:meth:`arrived_fingers`)."""
        return self.arrived_fingers(states).all(1)

    def posture(self, x: np.ndarray) -> Posture:
        """The :class:`Posture` of a state (1-D, internal units)."""
        return self.postures(x[None])[0]

    def postures(self, states: np.ndarray) -> list[Posture]:
        """The :class:`Posture` of each state (B, n) (:func:`state_postures`)."""
        return state_postures(self.robot, self.layout, states)

    def state(self, posture: Posture) -> np.ndarray:
        """The state (1-D) of a posture."""
        head = head_of(self.robot).values(posture)
        fingers = posture.fingers[torch.as_tensor(self.robot.finger_mask)]
        return np.concatenate([head.numpy().astype(np.float64), fingers.numpy().astype(np.float64)])

    def link_frames(self, states: np.ndarray) -> tuple[list[str], np.ndarray]:
        """The links' names and world poses (B, L, 4, 4) in states (B, n)."""
        robot, m = self.robot, self.layout.body
        x = torch.as_tensor(np.asarray(states, dtype=np.float64))
        return head_of(robot).link_frames(x[:, :m], _finger_joints(robot, x, m))

    def clear(self, states: np.ndarray) -> np.ndarray:
        """(B,) which states (B, n) are clear (module docstring)."""
        self.checks += len(states)
        links, frames = self.link_frames(states)
        touching = self._arrived_at(links, frames).astype(np.float64) @ self._distal > 0
        return ~self.scene.collides_at(links, frames, touching)

    def _arrived_at(self, links: list[str], frames: np.ndarray) -> np.ndarray:
        """:meth:`arrived_fingers` from the states' link frames (B, L, 4, 4): the marked points
        (fingertips, a gripper's points) read off their links' frames, no second kinematics."""
        if self.problem.fingers:
            _, points = self.robot.tip_frames_at(links, frames, self.problem.fingers)
        else:
            _, points = self.robot.points_on_links(links, frames, self.robot.cfg.gripper_points)
        targets = self._targets.numpy()
        if not self.problem.fingers:  # a gripper's two points, either pairing
            d = np.minimum(np.linalg.norm(points - targets, axis=-1).max(-1),
                           np.linalg.norm(points - targets[::-1], axis=-1).max(-1))
            return (d <= self.touch)[:, None]
        return np.linalg.norm(points - targets, axis=-1) <= self.touch

    def strictly_clear(self, states: np.ndarray) -> np.ndarray:
        """(B,) which states (B, n) are clear with no link touching the object (not even the
        contact fingertips where they have arrived)."""
        self.checks += len(states)
        return ~self.scene.collides_at(*self.link_frames(states))

    def first_collision(self, a: np.ndarray, b: np.ndarray, resolution_deg: float, resolution_mm: float,
                        batch: int = 32) -> int | None:
        """The straight motion from a to b in steps within the resolution: the index of a colliding
        state (0 = a; the states are tested ends first, then by halving), or None when it is clear
        throughout (both ends included)."""
        n = self.layout.steps(a, b, resolution_deg, resolution_mm)
        order = _bisection_order(n + 1)  # the ends, the middle, the quarters, ...: a collision is found early
        s = np.linspace(0.0, 1.0, n + 1)
        for start in range(0, n + 1, batch):
            part = order[start: start + batch]
            ok = self.clear(a + s[part, None] * (b - a))
            if not ok.all():
                return int(part[~ok].min())
        return None


def _bisection_order(count: int) -> np.ndarray:
    """Indices 0..count-1: both ends first, then the midpoints of ever finer halvings."""
    if count <= 2:
        return np.arange(count)
    order, seen = [0, count - 1], {0, count - 1}
    step = count - 1
    while step > 1:
        half = step // 2 if step % 2 == 0 else (step + 1) // 2
        for k in range(0, count - 1, step):
            mid = min(k + half, count - 1)
            if mid not in seen:
                seen.add(mid)
                order.append(mid)
        step = half
    order += [k for k in range(count) if k not in seen]
    return np.asarray(order)
