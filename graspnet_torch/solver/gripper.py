"""The gripper's environment (MANUS, paper section 7): 9 joints -> two gripper points -> eq. 24-29.

The configuration network chooses the mobile base (x, y, yaw) and the arm's joints (n = 9 for
``manus``); forward kinematics places the two points marked on the jaws; the evaluation is
d (eq. 26-28: the smaller of the two pairings' summed distances, metres) and the alignment
|n_gripper . n_object| (eq. 24), from which :class:`~graspnet_torch.rewards.Reward` builds
R = (R1 + R2) / 2 (eq. 29), shaped by the collision count (R2-R4) when the problem has an object
or obstacles. No FCNN.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.rewards import manus_reward
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.environment import Evaluation
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["GripperEnvironment", "gripper_bounds"]


def gripper_bounds(robot: Robot, problem: GraspProblem, approach_m: float = 0.2,
                   approach_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """(n,) bounds of the body joints (m / rad): the joint limits, or +- (approach_m, approach_deg)
    about the problem's ``approach`` within them (joints the approach leaves out: their limits)."""
    lower, upper = (a.copy() for a in robot.body_limits)
    if problem.approach is None:
        return lower, upper
    names = robot.body_joint_names
    unknown = sorted(set(problem.approach) - set(names))
    if unknown:
        raise ProblemError(f"{problem.source}: approach: unknown joint(s) {', '.join(unknown[:5])} of robot "
                           f"'{robot.name}' (joints: {', '.join(names)})")
    for k, (name, kind) in enumerate(zip(names, robot.body.joint_types, strict=True)):
        if name not in problem.approach:
            continue
        value = problem.approach[name] * (math.pi / 180 if kind == "revolute" else 1.0)
        if not lower[k] - 1e-9 <= value <= upper[k] + 1e-9:
            unit = "degrees" if kind == "revolute" else "m"
            scale = 180 / math.pi if kind == "revolute" else 1.0
            raise ProblemError(f"{problem.source}: approach.{name}: {problem.approach[name]:g} lies outside its "
                               f"limits [{lower[k] * scale:.4g}, {upper[k] * scale:.4g}] {unit}")
        half = math.radians(approach_deg) if kind == "revolute" else approach_m
        lower[k], upper[k] = max(lower[k], value - half), min(upper[k], value + half)
    return lower, upper


class GripperEnvironment:
    """Evaluates body configurations of a gripper robot for one two-point problem, batched.

    Attributes:
        n: body joints (9 for ``manus``: base x, y, yaw + 6 arm joints).
        lower, upper: (n,) search bounds (m / rad).
    """

    def __init__(self, robot: Robot, problem: GraspProblem, dtype: torch.dtype = torch.float32,
                 device: torch.device | str = "cpu", collisions: bool = False, approach_m: float = 0.2,
                 approach_deg: float = 30.0):
        if robot.gripper_kernel is None or problem.points is None:
            raise ProblemError(f"{problem.source}: robot '{robot.name}' has no gripper points or the problem no "
                               f"'points'")
        self.robot, self.problem = robot, problem
        self.n = len(robot.body_joint_names)
        self._bounds = gripper_bounds(robot, problem, approach_m, approach_deg)
        self.lower = torch.as_tensor(self._bounds[0], dtype=dtype, device=device)
        self.upper = torch.as_tensor(self._bounds[1], dtype=dtype, device=device)
        self.targets = torch.as_tensor(problem.points_world(), dtype=dtype, device=device)  # (2, 3)
        self.proxy = None
        if collisions and (problem.object is not None or problem.obstacles):
            from graspnet_torch.collision.proxy import CollisionProxy

            self.proxy = CollisionProxy(robot, problem, dtype=dtype, device=device)
            self._no_fingers = torch.zeros(1, 0, 0, dtype=dtype, device=device)

    def evaluate(self, config: Tensor) -> Evaluation:
        """config: (T, n) -> d (T,) of eq. 26 as ``error``, the alignment (T,) of eq. 24 and, with a
        proxy, the collision count."""
        points = self.robot.gripper_points(config)  # (T, 2, 3)
        _r, alignment, _r2, d = manus_reward(points, self.targets.expand_as(points))
        collisions = None
        if self.proxy is not None:
            levels, palm = self.proxy.body_levels_and_palm(config)
            collisions = self.proxy.count(palm, self._no_fingers.expand(config.shape[0], 0, 0), config, levels)
        return Evaluation(error=d, alignment=alignment, collisions=collisions)

    def finish(self, config: Tensor, evaluation: Evaluation, iterations: int) -> tuple[Tensor, Evaluation]:
        """Polish the reported configurations: ``iterations`` damped least-squares steps (float64)
        on the two gripper points against the object points of each trial's nearer pairing,
        within the bounds, each step kept only where it lowers d (never worse). The analogue of
        the hand's final finger refinement: the loop finds the basin, the polish lands in it.

            dq = J^T (J J^T + lambda^2 I)^-1 e,   J = d(points)/dq (6 x n, forward differences, float64)
        """
        if iterations <= 0:
            return config, evaluation
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        q = self.clamp(config)
        targets = torch.as_tensor(self.problem.points_world(), dtype=torch.float64)
        swap = _pairing(self.robot.gripper_points(q), targets)  # (T,) True: point 1 -> target 2
        goal = torch.where(swap.view(-1, 1, 1), targets.flip(0), targets).reshape(-1, 6)
        lam, h = 1e-3, 1e-6
        eye = torch.eye(self.n, dtype=torch.float64)
        for _ in range(iterations):
            pts = self.robot.gripper_points(q).reshape(-1, 6)
            e = goal - pts
            shifted = q.unsqueeze(1) + h * eye  # (T, n, n): one joint moved per row
            J = (self.robot.gripper_points(shifted).reshape(q.shape[0], self.n, 6)
                 - pts.reshape(-1, 1, 6)).transpose(1, 2) / h  # (T, 6, n)
            A = J @ J.transpose(1, 2) + lam ** 2 * torch.eye(6, dtype=torch.float64)
            dq = (J.transpose(1, 2) @ torch.linalg.solve(A, e.unsqueeze(-1))).squeeze(-1)
            new = torch.clamp(q + dq, lo, hi)
            better = (goal - self.robot.gripper_points(new).reshape(-1, 6)).norm(dim=-1) < e.norm(dim=-1)
            q = torch.where(better.unsqueeze(1), new, q)
        ev = self.evaluate(q.to(config))
        return q.to(config), ev

    def clamp(self, config: Tensor) -> Tensor:
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        return torch.clamp(config.detach().to(torch.float64).cpu(), lo, hi)

    def report(self, config: Tensor, evaluation: Evaluation) -> list[dict]:
        """Per trial, recomputed in float64: every body joint by name (m / degrees), the palm
        (gripper) pose, the two gripper points, d in mm, the alignment and ``error`` (d, metres)."""
        from graspnet_torch.robot.transforms import rt_to_pose

        q = self.clamp(config)
        points = self.robot.gripper_points(q)
        targets = torch.as_tensor(self.problem.points_world(), dtype=torch.float64)
        _r, alignment, _r2, d = manus_reward(points, targets.expand_as(points))
        palm = rt_to_pose(*self.robot.palm_frame(q))
        deg = 180.0 / math.pi
        scale = [deg if kind == "revolute" else 1.0 for kind in self.robot.body.joint_types]
        out = []
        for k in range(q.shape[0]):
            pose = palm[k].tolist()
            out.append({
                "arm_joints": {n: v * s for n, v, s in zip(self.robot.body_joint_names, q[k].tolist(), scale,
                                                           strict=True)},
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "gripper_points": points[k].tolist(),
                "distance_mm": float(d[k]) * 1000,
                "alignment": float(alignment[k]),
                "error": float(d[k]),
            })
        return out


def _pairing(points: Tensor, targets: Tensor) -> Tensor:
    """(T,) True where the crossed pairing (eq. 28) is the nearer: gripper point 1 -> object point 2."""
    d1 = (targets - points).norm(dim=-1).sum(-1)
    d2 = (targets.flip(0) - points).norm(dim=-1).sum(-1)
    return d2 < d1
