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

from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.rewards import manus_reward
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.environment import Evaluation
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["CLEARANCE_M", "GripperEnvironment", "gripper_bounds"]

CLEARANCE_M = 0.005  # the loop and the polish keep 5 mm from obstacles, floor and own links (proxy margin)


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
                 approach_deg: float = 30.0, refine: int = 0):
        if robot.gripper_kernel is None or problem.points is None:
            raise ProblemError(f"{problem.source}: robot '{robot.name}' has no gripper points or the problem no "
                               f"'points'")
        self.robot, self.problem = robot, problem
        self.n = len(robot.body_joint_names)
        self.refine = refine
        self._bounds = gripper_bounds(robot, problem, approach_m, approach_deg)
        self.lower = torch.as_tensor(self._bounds[0], dtype=dtype, device=device)
        self.upper = torch.as_tensor(self._bounds[1], dtype=dtype, device=device)
        self.targets = torch.as_tensor(problem.points_world(), dtype=dtype, device=device)  # (2, 3)
        self.proxy = None
        if collisions and has_environment(robot, problem):
            from graspnet_torch.collision.proxy import CollisionProxy

            self.proxy = CollisionProxy(robot, problem, dtype=dtype, device=device, clearance=CLEARANCE_M)
            self._no_fingers = torch.zeros(1, 0, 0, dtype=dtype, device=device)

    def evaluate(self, config: Tensor) -> Evaluation:
        """config: (T, n) -> d (T,) of eq. 26 as ``error``, the alignment (T,) of eq. 24 and, with a
        proxy, the collision count."""
        proposal = config
        if self.refine > 0:
            config = self._refine(config, self.refine)
        points = self.robot.gripper_points(config)  # (T, 2, 3)
        _r, alignment, _r2, d = manus_reward(points, self.targets.expand_as(points))
        collisions = None
        if self.proxy is not None:
            levels, palm = self.proxy.body_levels_and_palm(config)
            collisions = self.proxy.count(palm, self._no_fingers.expand(config.shape[0], 0, 0), config, levels)
        return Evaluation(error=d, alignment=alignment, collisions=collisions,
                          config=config if config is not proposal else None)

    def _refine(self, q: Tensor, steps: int) -> Tensor:
        """``steps`` damped least-squares steps (lambda = 0.05, forward differences h = 1e-3 in the
        loop's dtype, no collision test) towards each trial's nearer pairing, within the bounds,
        each kept where it lowers the point error: the learner proposes, a few local steps
        settle the proposal, and the settled configuration is what is evaluated and reported."""
        T = q.shape[0]
        tg = self.targets
        pts = self.robot.gripper_points(q)
        swap = _pairing(pts, tg)
        goal = torch.where(swap.view(-1, 1, 1), tg.flip(0), tg).reshape(T, 6)
        pts = pts.reshape(T, 6)
        err = (goal - pts).norm(dim=-1)
        h = 1e-3
        eye = torch.eye(self.n, dtype=q.dtype, device=q.device)
        eye6 = torch.eye(6, dtype=q.dtype, device=q.device)
        lam = torch.full((T, 1, 1), 0.05, dtype=q.dtype, device=q.device)
        for _ in range(steps):
            J = (self.robot.gripper_points(q.unsqueeze(1) + h * eye).reshape(T, self.n, 6)
                 - pts.unsqueeze(1)).transpose(1, 2) / h
            new = torch.minimum(torch.maximum(q + _dls(J, goal - pts, lam, eye6), self.lower), self.upper)
            new_pts = self.robot.gripper_points(new).reshape(T, 6)
            new_err = (goal - new_pts).norm(dim=-1)
            better = (new_err < err).unsqueeze(1)
            q, pts, err = torch.where(better, new, q), torch.where(better, new_pts, pts), torch.minimum(new_err, err)
        return q

    def finish(self, config: Tensor, evaluation: Evaluation, iterations: int) -> tuple[Tensor, Evaluation]:
        """Polish the reported configurations: ``iterations`` damped least-squares steps (float64)
        on the two gripper points against the object points of each trial's nearer pairing,
        within the bounds, each step kept only where it lowers d (never worse). The analogue of
        the hand's final finger refinement: the loop finds the basin, the polish lands in it.

            dq = J^T (J J^T + lambda^2 I)^-1 e,   J = d(points)/dq (6 x n, forward differences, float64)
        """
        if iterations <= 0:
            return config, evaluation
        q = self.clamp(config)
        T = q.shape[0]
        targets = torch.as_tensor(self.problem.points_world(), dtype=torch.float64)
        goal = torch.cat([targets.reshape(1, 6).expand(T, 6), targets.flip(0).reshape(1, 6).expand(T, 6)])
        q2, err = self._least_squares(q.repeat(2, 1), goal, iterations)  # both pairings (eq. 26-28) at once
        crossed = err[T:] < err[:T]
        q = torch.where(crossed.unsqueeze(1), q2[T:], q2[:T])
        ev = self.evaluate(q.to(config))
        return q.to(config), ev

    def _least_squares(self, q: Tensor, goal: Tensor, iterations: int) -> tuple[Tensor, Tensor]:
        """Levenberg-Marquardt on the gripper points, float64, within the bounds.

        q: (B, n) start; goal: (B, 6) the two object points in the chosen pairing. Per row, a step
        dq = J^T (J J^T + lambda^2 I)^-1 e is kept only where it lowers |e| (then lambda / 3), else
        lambda * 4. Returns the configurations (B, n) and their |e| (B,).
        """
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        h = 1e-6
        lam = torch.full((q.shape[0], 1, 1), 1e-2, dtype=torch.float64)
        eye6 = torch.eye(6, dtype=torch.float64)
        eye = torch.eye(self.n, dtype=torch.float64)
        pts = self.robot.gripper_points(q).reshape(-1, 6)
        err = (goal - pts).norm(dim=-1)
        collisions = self._count(q) if self.proxy is not None else None
        for _ in range(iterations):
            e = goal - pts
            shifted = q.unsqueeze(1) + h * eye  # (B, n, n): one joint moved per row
            J = (self.robot.gripper_points(shifted).reshape(q.shape[0], self.n, 6)
                 - pts.reshape(-1, 1, 6)).transpose(1, 2) / h  # (B, 6, n), forward differences
            dq = _dls(J, e, lam, eye6)
            # joints at a bound that the step pushes outward leave the Jacobian (an active set)
            blocked = ((q <= lo + 1e-9) & (dq < 0)) | ((q >= hi - 1e-9) & (dq > 0))
            if bool(blocked.any()):
                dq = _dls(J * (~blocked).unsqueeze(1), e, lam, eye6)
            new = torch.clamp(q + dq, lo, hi)
            new_pts = self.robot.gripper_points(new).reshape(-1, 6)
            new_err = (goal - new_pts).norm(dim=-1)
            better = new_err < err
            if collisions is not None:  # never into a collision: a step may not raise the proxy's count
                new_c = self._count(new)
                better &= new_c <= collisions
                collisions = torch.where(better, new_c, collisions)
            q = torch.where(better.unsqueeze(1), new, q)
            pts = torch.where(better.unsqueeze(1), new_pts, pts)
            err = torch.where(better, new_err, err)
            lam = torch.where(better.view(-1, 1, 1), (lam / 3).clamp(min=1e-4), (lam * 4).clamp(max=10.0))
        return q, err

    def _count(self, q: Tensor) -> Tensor:
        """(B,) the proxy's collision count of float64 configurations (B, n)."""
        config = q.to(self.lower)
        levels, palm = self.proxy.body_levels_and_palm(config)
        return self.proxy.count(palm, self._no_fingers.expand(config.shape[0], 0, 0), config, levels).cpu()

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


def _dls(J: Tensor, e: Tensor, lam: Tensor, eye: Tensor) -> Tensor:
    """dq = J^T (J J^T + lambda^2 I)^-1 e: J (B, 6, n), e (B, 6), lam (B, 1, 1) -> (B, n)."""
    return (J.transpose(1, 2) @ torch.linalg.solve(J @ J.transpose(1, 2) + lam ** 2 * eye, e.unsqueeze(-1))).squeeze(-1)


def _pairing(points: Tensor, targets: Tensor) -> Tensor:
    """(T,) True where the crossed pairing (eq. 28) is the nearer: gripper point 1 -> object point 2."""
    d1 = (targets - points).norm(dim=-1).sum(-1)
    d2 = (targets.flip(0) - points).norm(dim=-1).sum(-1)
    return d2 < d1
