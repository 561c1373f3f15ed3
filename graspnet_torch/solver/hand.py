"""The hand's environment: a palm pose -> contacts in each finger's frame -> FCNN -> errors.

Steps 2-4 of section 2.4 for the HCNN: with the palm at a candidate pose, the contacts (fixed in
the world) are expressed in each finger's base frame, the FCNN gives the finger joints, and
forward kinematics gives each fingertip's error (eq. 3, computed in the finger frames).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import pose_to_rt, untransform_points
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["HandEnvironment"]


class HandEnvironment:
    """Evaluates palm poses for one problem, batched over trials.

    Attributes:
        n: size of the configuration (6: x, y, z, rx, ry, rz).
        lower, upper: (6,) search bounds (m, rad).
        fingers: the contact fingers, in problem order.
    """

    n = 6

    def __init__(self, robot: Robot, problem: GraspProblem, ik: FingerIK, refine: int = 1, candidates: int = 1,
                 dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu"):
        if robot.has_body:
            raise ProblemError(f"{problem.source}: robot '{robot.name}' has an arm; the HCNN solves free hands")
        missing = [f for f in problem.fingers if f not in ik.experts]
        if missing:
            raise ProblemError(f"{problem.source}: no FCNN experts for finger(s) {', '.join(missing)}")
        self.robot, self.problem, self.ik = robot, problem, ik
        self.refine, self.candidates = refine, candidates
        self.fingers = problem.fingers
        idx = [robot.finger_index(f) for f in self.fingers]
        bounds = problem.bounds()
        self.lower = torch.as_tensor(bounds.lower, dtype=dtype, device=device)
        self.upper = torch.as_tensor(bounds.upper, dtype=dtype, device=device)
        self.contacts = torch.as_tensor(problem.contacts_world(), dtype=dtype, device=device)  # (F, 3)
        base = torch.as_tensor(np.stack([robot.fingers[robot.finger_names[i]].base_in_palm for i in idx]),
                               dtype=dtype, device=device)
        self.base_R, self.base_t = base[:, :3, :3], base[:, :3, 3]
        ik._bank(tuple(self.fingers), dtype, torch.device(device))  # build the finger kernels now, not in the loop

    def targets(self, palm_pose: Tensor) -> Tensor:
        """Contacts in each finger's base frame. palm_pose: (T, 6) -> (T, F, 3)."""
        R, t = pose_to_rt(palm_pose)
        in_palm = untransform_points(R.unsqueeze(1), t.unsqueeze(1), self.contacts)
        return untransform_points(self.base_R, self.base_t, in_palm)

    def evaluate(self, palm_pose: Tensor) -> tuple[Tensor, Tensor]:
        """Finger joints and fingertip errors for palm poses.

        palm_pose: (T, 6) -> q: (T, F, n) within limits, error: (T, F) metres.
        """
        targets = self.targets(palm_pose)
        if self.candidates > 1 and self.refine > 0:
            return self.ik.solve_fingers(targets, self.fingers, self.refine, self.candidates)
        if self.refine <= 0:
            return self.ik.compete(targets, self.fingers)
        q, _err, tips, J = self.ik.compete_jacobian(targets, self.fingers)
        return self.ik.refine(q, targets, self.fingers, self.refine, start=(tips, J))
