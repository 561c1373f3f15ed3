"""The arm's environment (ACNN, paper section 6): arm joints -> palm frame -> FCNN fingers -> errors.

The configuration network chooses the arm's joints (n = 7 for ``arm_hand``) within the problem's
``bounds`` (default: the joint limits); the arm's forward kinematics places the palm, the contacts
(fixed in the world) are expressed in each finger's base frame, the FCNN gives the finger joints
and forward kinematics each fingertip's error (eq. 3, in the finger frames), as in Fig. 5b.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.fingers import FingerEnvironment
from graspnet_torch.solver.search_space import finger_reach, finger_reach_bound
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ArmHandEnvironment", "arm_bounds"]


def arm_bounds(robot: Robot, problem: GraspProblem) -> tuple[np.ndarray, np.ndarray]:
    """(m,) lower and upper bounds of the arm joints (radians / metres): the problem's ``bounds``
    (degrees for revolute joints) within the joint limits, else the joint limits."""
    lower, upper = robot.body_limits
    if problem.joint_bounds is None:
        return lower.copy(), upper.copy()
    lo, hi = problem.joint_bounds
    m = len(robot.body_joint_names)
    if lo.shape != (m,):
        raise ProblemError(f"{problem.source}: bounds: robot '{robot.name}' has {m} arm joints "
                           f"({', '.join(robot.body_joint_names)}), got {lo.size} values")
    scale = np.array([math.pi / 180 if t == "revolute" else 1.0 for t in robot.body.joint_types])
    lo, hi = np.maximum(lo * scale, lower), np.minimum(hi * scale, upper)
    if np.any(lo > hi):
        bad = [robot.body_joint_names[i] for i in np.nonzero(lo > hi)[0]]
        raise ProblemError(f"{problem.source}: bounds: the range of {', '.join(bad)} lies outside its joint limits")
    return lo, hi


class ArmHandEnvironment(FingerEnvironment):
    """Evaluates arm configurations for one problem, batched over trials.

    Attributes:
        n: arm joints (7 for ``arm_hand``), then the joints the fingers share (if any).
        m: arm joints.
        lower, upper: (n,) search bounds (radians / metres).
        fingers: the contact fingers, in problem order.
    """

    def __init__(self, robot: Robot, problem: GraspProblem | Sequence[GraspProblem], solver: SolverCfg,
                 ik: FingerIK | None, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu",
                 collisions: bool = False, runs: int = 1):
        if not robot.has_body or robot.n_fingers == 0:
            first = problem if isinstance(problem, GraspProblem) else problem[0]
            raise ProblemError(f"{first.source}: robot '{robot.name}' is not an arm with fingers")
        super().__init__(robot, problem, solver, ik, dtype, device, collisions, runs)
        self.m = self.n = len(robot.body_joint_names)
        bounds = [arm_bounds(robot, p) for p in self.problems]
        lo = np.stack([b[0] for b in bounds])
        hi = np.stack([b[1] for b in bounds])
        shared = robot.shared
        if shared.n:  # the joints the fingers share join the arm's (robot/shared.py)
            self.n, self.shared_slots = self.m + shared.n, shared.n
            lo = np.concatenate([lo, np.broadcast_to(shared.lower, (len(lo), shared.n))], axis=1)
            hi = np.concatenate([hi, np.broadcast_to(shared.upper, (len(hi), shared.n))], axis=1)
        if len(self.problems) > 1:
            lo, hi = np.repeat(lo, runs, axis=0), np.repeat(hi, runs, axis=0)  # (T, n)
        else:
            lo, hi = lo[0], hi[0]  # (n,)
        self._bounds64 = (torch.as_tensor(lo, dtype=torch.float64), torch.as_tensor(hi, dtype=torch.float64))
        self.lower = torch.as_tensor(lo, dtype=dtype, device=device)
        self.upper = torch.as_tensor(hi, dtype=dtype, device=device)

    def palm_frame(self, config: Tensor) -> tuple[Tensor, Tensor]:
        """The arm's forward kinematics of the configuration's first m columns (the arm joints).
        (T, n) -> R (T, 3, 3), t (T, 3)."""
        return self.robot.palm_frame(config[..., : self.m])

    def palm_frame_jacobian(self, config: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """The arm's forward kinematics and geometric Jacobian. (T, n) -> R (T, 3, 3), t (T, 3), J (T, 6, n)
        (zero in the shared joints' columns: they do not move the palm)."""
        R, t, J = self.robot.palm_frame_jacobian(config[..., : self.m])
        if self.shared_slots:
            J = torch.cat([J, J.new_zeros(*J.shape[:-1], self.shared_slots)], dim=-1)
        return R, t, J

    def _exact_bounds(self) -> tuple[Tensor, Tensor]:
        return self._bounds64

    def _palm_and_levels(self, config: Tensor) -> tuple[tuple[Tensor, Tensor], list[Tensor] | None]:
        """With a collision proxy, its arm chain gives the palm too (one pass of forward kinematics)."""
        if self.proxy is None:
            return self.palm_frame(config), None
        levels, palm = self.proxy.body_levels_and_palm(config[:, : self.m])
        return palm, levels

    def body(self, config: Tensor) -> Tensor:
        return config[:, : self.m]

    def _config_of(self, posture: Posture) -> Tensor:
        """The posture's arm joints (1, n) (then the shared joints, where they are)."""
        config = posture.body.to(torch.float64).reshape(1, -1)
        if self.shared_slots:
            shared = posture.shared if posture.shared is not None else torch.as_tensor(self.robot.shared_reference)
            config = torch.cat([config, shared.to(config).reshape(1, -1)], dim=1)
        return config

    def _add_fields(self, fields: list[dict], config: Tensor) -> None:
        """``arm_joints`` by URDF joint name in chain order (degrees; metres for prismatic joints)."""
        for k, f in enumerate(fields):
            f["arm_joints"] = self.robot.body_joints_to_file(config[k, : self.m])

    @classmethod
    def check(cls, robot: Robot, problem: GraspProblem, solver: SolverCfg) -> None:
        """Refuse a contact farther from the arm's first joint than the arm's links, their
        prismatic travel and the finger can reach; and ``bounds`` that do not fit the arm."""
        origin, arm = _arm_reach(robot)
        for contact, point in zip(problem.contacts, problem.contacts_world(), strict=True):
            reach = arm + finger_reach_bound(robot, contact.finger)
            gap = float(np.linalg.norm(point - origin))
            if gap > reach:
                raise ProblemError(f"{problem.source}: the {contact.finger} contact lies {gap:.3f} m from the arm's "
                                   f"first joint but the arm and {contact.finger} reach at most {reach:.3f} m")

    @classmethod
    def unreachable(cls, robot: Robot, problem: GraspProblem) -> list[str]:
        """The contact fingers whose contact lies farther from the arm's first joint than the arm's
        links (and prismatic travel) and the finger's sampled reach."""
        if not problem.contacts:
            return []
        origin, arm = _arm_reach(robot)
        gap = np.linalg.norm(problem.contacts_world() - origin, axis=1) - arm
        reach = finger_reach(robot)
        return [c.finger for c, g in zip(problem.contacts, gap, strict=True) if g > reach[robot.finger_index(c.finger)]]


def _arm_reach(robot: Robot) -> tuple[np.ndarray, float]:
    """The arm's first joint in the world and the most its links and prismatic travel reach."""
    body = robot.body
    arm = float(np.linalg.norm(body.offsets[1:, :3, 3], axis=1).sum())
    arm += sum(max(abs(lo), abs(hi)) for lo, hi, kind in zip(body.lower, body.upper, body.joint_types, strict=True)
               if kind == "prismatic")
    return body.offsets[0][:3, 3], arm
