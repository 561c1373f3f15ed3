"""The arm's environment (ACNN, paper section 6): arm joints -> palm frame -> FCNN fingers -> errors.

The configuration network chooses the arm's joints (n = 7 for ``arm_hand``) within the problem's
``bounds`` (default: the joint limits); the arm's forward kinematics places the palm, the contacts
(fixed in the world) are expressed in each finger's base frame, the FCNN gives the finger joints
and forward kinematics each fingertip's error (eq. 3, in the finger frames), as in Fig. 5b.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import rt_to_pose, untransform_points
from graspnet_torch.solver.environment import Evaluation
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


class ArmHandEnvironment:
    """Evaluates arm configurations for one problem, batched over trials.

    Attributes:
        n: arm joints (7 for ``arm_hand``).
        lower, upper: (n,) search bounds (radians / metres).
        fingers: the contact fingers, in problem order.
    """

    def __init__(self, robot: Robot, problem: GraspProblem, ik: FingerIK, refine: int = 0, candidates: int = 1,
                 dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu"):
        if not robot.has_body or robot.n_fingers == 0:
            raise ProblemError(f"{problem.source}: robot '{robot.name}' is not an arm with fingers")
        missing = [f for f in problem.fingers if f not in ik.experts]
        if missing:
            raise ProblemError(f"{problem.source}: no FCNN experts for finger(s) {', '.join(missing)}")
        self.robot, self.problem, self.ik = robot, problem, ik
        self.refine, self.candidates = refine, candidates
        self.fingers = problem.fingers
        self.n = len(robot.body_joint_names)
        self.idx = [robot.finger_index(f) for f in self.fingers]
        lo, hi = arm_bounds(robot, problem)
        self.lower = torch.as_tensor(lo, dtype=dtype, device=device)
        self.upper = torch.as_tensor(hi, dtype=dtype, device=device)
        self.contacts = torch.as_tensor(problem.contacts_world(), dtype=dtype, device=device)  # (F, 3)
        base = torch.as_tensor(np.stack([robot.fingers[robot.finger_names[i]].base_in_palm for i in self.idx]),
                               dtype=dtype, device=device)
        self.base_R, self.base_t = base[:, :3, :3], base[:, :3, 3]
        ik._bank(tuple(self.fingers), dtype, torch.device(device))

    def targets(self, q_arm: Tensor) -> Tensor:
        """Contacts in each finger's base frame. q_arm: (T, n) -> (T, F, 3)."""
        R, t = self.robot.palm_frame(q_arm)
        in_palm = untransform_points(R.unsqueeze(1), t.unsqueeze(1), self.contacts)
        return untransform_points(self.base_R, self.base_t, in_palm)

    def evaluate(self, q_arm: Tensor) -> Evaluation:
        """q_arm: (T, n) -> E (T,) of eq. 3, per-finger errors (T, F), finger joints (T, F, j)."""
        targets = self.targets(q_arm)
        if self.refine > 0:
            q, err = self.ik.solve_fingers(targets, self.fingers, self.refine, self.candidates)
        else:
            q, err = self.ik.compete(targets, self.fingers)
        return Evaluation(error=err.sum(dim=1), finger_errors=err, joints=q)

    def finish(self, config: Tensor, evaluation: Evaluation, iterations: int) -> Evaluation:
        """Refine the finger joints of the reported configurations (arm joints kept); never worse."""
        if iterations <= 0:
            return evaluation
        with torch.inference_mode():
            q, err = self.ik.refine(evaluation.joints, self.targets(config), self.fingers, iterations)
        return Evaluation(error=err.sum(dim=1).clone(), finger_errors=err.clone(), joints=q.clone(),
                          collisions=evaluation.collisions)

    def report(self, config: Tensor, evaluation: Evaluation) -> list[dict]:
        """Per trial: arm joints by name, the palm pose the arm's FK gives, every finger's joints and
        the fingertip errors, recomputed in float64 (configuration clamped to the exact bounds)."""
        robot, problem = self.robot, self.problem
        lo, hi = arm_bounds(robot, problem)
        q_arm = torch.clamp(config.detach().to(torch.float64).cpu(), torch.as_tensor(lo), torch.as_tensor(hi))
        T = q_arm.shape[0]
        flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
        q = robot.home_posture(torch.float64).fingers.expand(T, -1, -1).clone()
        q[:, self.idx] = torch.clamp(evaluation.joints.detach().to(torch.float64).cpu(), flo[self.idx],
                                     fhi[self.idx])
        tips = robot.fingertips_world_from_body(q_arm, q)[:, self.idx]
        contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)
        err = torch.linalg.vector_norm(tips - contacts, dim=-1)
        R, t = robot.palm_frame(q_arm)
        palm = rt_to_pose(R, t)
        deg = 180.0 / math.pi
        scale = [deg if kind == "revolute" else 1.0 for kind in robot.body.joint_types]
        out = []
        for k in range(T):
            pose = palm[k].tolist()
            out.append({
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "arm_joints": {name: v * s for name, v, s in zip(robot.body_joint_names, q_arm[k].tolist(), scale,
                                                                 strict=True)},
                "joints": {f: [v * deg for v in q[k, j].tolist()] for j, f in enumerate(robot.finger_names)},
                "fingertip_error_mm": {f: float(err[k, j]) * 1000 for j, f in enumerate(problem.fingers)},
                "error": float(err[k].sum()),
            })
        return out
