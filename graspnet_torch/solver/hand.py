"""The hand's environment: a palm pose -> contacts in each finger's frame -> FCNN -> errors.

Steps 2-4 of section 2.4 for the HCNN: with the palm at a candidate pose, the contacts (fixed in
the world) are expressed in each finger's base frame, the FCNN gives the finger joints, and
forward kinematics gives each fingertip's error (eq. 3, computed in the finger frames).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import pose_to_rt, untransform_points
from graspnet_torch.solver.environment import Evaluation
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["HandEnvironment", "check_reach"]


def check_reach(robot: Robot, problem: GraspProblem) -> None:
    """Refuse a contact that no palm pose within the bounds can bring a fingertip to: farther from
    the box of palm positions than the finger can reach (its base offset plus the lengths of its
    links, an upper bound whatever the joints). Robots with an arm are left to their environment."""
    if robot.has_body:
        return
    bounds = problem.bounds()
    lo, hi = bounds.lower[:3], bounds.upper[:3]
    for contact, point in zip(problem.contacts, problem.contacts_world(), strict=True):
        spec = robot.fingers[contact.finger]
        offsets = spec.chain.offsets[:, :3, 3]
        reach = float(np.linalg.norm(spec.base_in_palm[:3, 3]) + np.linalg.norm(offsets, axis=1).sum())
        gap = float(np.linalg.norm(point - np.clip(point, lo, hi)))
        if gap > reach:
            raise ProblemError(f"{problem.source}: the {contact.finger} contact lies {gap:.3f} m from the palm's "
                               f"search space but the {contact.finger} reaches at most {reach:.3f} m from the palm")


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

    def finger_joints(self, palm_pose: Tensor) -> tuple[Tensor, Tensor]:
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

    def evaluate(self, palm_pose: Tensor) -> Evaluation:
        """palm_pose: (T, 6) -> E (T,) of eq. 3, per-finger errors (T, F), finger joints (T, F, n)."""
        q, errors = self.finger_joints(palm_pose)
        return Evaluation(error=errors.sum(dim=1), finger_errors=errors, joints=q)

    def finish(self, config: Tensor, evaluation: Evaluation, iterations: int) -> Evaluation:
        """Refine the finger joints of the reported configurations (palm poses kept); never worse."""
        if iterations <= 0:
            return evaluation
        with torch.inference_mode():
            targets = self.targets(config)
            q, err = self.ik.refine(evaluation.joints, targets, self.fingers, iterations)
        return Evaluation(error=err.sum(dim=1).clone(), finger_errors=err.clone(), joints=q.clone(),
                          collisions=evaluation.collisions)

    def report(self, config: Tensor, evaluation: Evaluation) -> list[dict]:
        """Per trial, the result fields of the reported configuration, errors recomputed in float64
        by FK against the contacts.

        The loop runs in float32, whose rounded limits can exceed the exact ones by ~1e-7 rad; the
        configuration is clamped to the exact (float64) bounds and limits first.
        """
        robot, problem = self.robot, self.problem
        bounds = problem.bounds()
        palm = config.detach().to(torch.float64).cpu()
        palm = torch.clamp(palm, torch.as_tensor(bounds.lower), torch.as_tensor(bounds.upper))
        T = palm.shape[0]
        idx = [robot.finger_index(f) for f in problem.fingers]
        flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
        q = robot.home_posture(torch.float64).fingers.expand(T, -1, -1).clone()
        q[:, idx] = torch.clamp(evaluation.joints.detach().to(torch.float64).cpu(), flo[idx], fhi[idx])
        tips = robot.fingertips_world(palm, q)[:, idx]
        contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)
        err = torch.linalg.vector_norm(tips - contacts, dim=-1)  # (T, F), metres
        deg = 180.0 / math.pi
        out = []
        for t in range(T):
            pose = palm[t].tolist()
            out.append({
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "joints": {f: [v * deg for v in q[t, k].tolist()] for k, f in enumerate(robot.finger_names)},
                "fingertip_error_mm": {f: float(err[t, k]) * 1000 for k, f in enumerate(problem.fingers)},
                "error": float(err[t].sum()),
            })
        return out
