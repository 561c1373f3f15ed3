"""The hand's environment: a palm pose -> contacts in each finger's frame -> FCNN -> errors.

Steps 2-4 of section 2.4 for the HCNN: with the palm at a candidate pose, the contacts (fixed in
the world) are expressed in each finger's base frame, the FCNN gives the finger joints, and
forward kinematics gives each fingertip's error (eq. 3, computed in the finger frames).
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
from graspnet_torch.robot.transforms import compose, pose_jacobian, pose_to_rt, rt_to_pose, untransform_points
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.fingers import FingerEnvironment
from graspnet_torch.solver.search_space import (
    PalmSearchSpace,
    contact_search_frame,
    finger_reach,
    finger_reach_bound,
    palm_search_space,
    palm_space_around,
)
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["HandEnvironment"]


class HandEnvironment(FingerEnvironment):
    """Evaluates palm poses for one problem, batched over trials.

    Each problem is solved in its palm search space's frame G
    (:func:`~graspnet_torch.solver.search_space.palm_search_space`): the problem is moved by G^-1
    (contacts, object, obstacles), the configuration is the palm pose in that frame, and
    :meth:`report` gives the palm pose in the world (G o pose).

    ``spaces`` (one per problem) replace the problems' own search spaces (:meth:`around`: a warm
    start's).

    Attributes:
        n: size of the configuration (6: x, y, z, rx, ry, rz).
        lower, upper: (6,) search bounds (m, rad), in the search frame.
        spaces: each problem's :class:`~graspnet_torch.solver.search_space.PalmSearchSpace`.
        fingers: the contact fingers, in problem order.
    """

    n = 6

    def __init__(self, robot: Robot, problem: GraspProblem | Sequence[GraspProblem], solver: SolverCfg,
                 ik: FingerIK | None, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu",
                 collisions: bool = False, runs: int = 1, spaces: Sequence[PalmSearchSpace] | None = None):

        problems = [problem] if isinstance(problem, GraspProblem) else list(problem)
        if robot.has_body:
            raise ProblemError(f"{problems[0].source}: robot '{robot.name}' has an arm; the HCNN solves free hands")
        self.spaces = list(spaces) if spaces is not None else [palm_search_space(robot, p) for p in problems]
        local = [p.moved(np.linalg.inv(s.frame)) for p, s in zip(problems, self.spaces, strict=True)]
        super().__init__(robot, local if len(local) > 1 else local[0], solver, ik, dtype, device, collisions, runs)
        self.world_problems = problems
        self._proposal: tuple[Tensor, Tensor] | None = None
        frames = np.stack([s.frame for s in self.spaces])
        lo = np.stack([s.lower for s in self.spaces])
        hi = np.stack([s.upper for s in self.spaces])
        shared = robot.shared
        if shared.n:  # the joints the fingers share join the palm pose (robot/shared.py)
            self.n, self.shared_slots = 6 + shared.n, shared.n
            lo = np.concatenate([lo, np.broadcast_to(shared.lower, (len(lo), shared.n))], axis=1)
            hi = np.concatenate([hi, np.broadcast_to(shared.upper, (len(hi), shared.n))], axis=1)
        if len(self.problems) > 1:
            lo, hi = np.repeat(lo, runs, axis=0), np.repeat(hi, runs, axis=0)  # (T, 6)
            frames = np.repeat(frames, runs, axis=0)
        else:
            lo, hi = lo[0], hi[0]  # (6,)
        frames = torch.as_tensor(frames, dtype=torch.float64)
        self.frame64 = (frames[:, :3, :3], frames[:, :3, 3])  # (T or 1, 3, 3), (T or 1, 3): G in the world
        self._bounds64 = (torch.as_tensor(lo, dtype=torch.float64), torch.as_tensor(hi, dtype=torch.float64))
        self.lower = torch.as_tensor(lo, dtype=dtype, device=device)
        self.upper = torch.as_tensor(hi, dtype=dtype, device=device)

    @classmethod
    def around(cls, robot: Robot, problem: GraspProblem, posture: Posture, solver: SolverCfg, ik: FingerIK | None,
               dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", collisions: bool = False
               ) -> HandEnvironment:
        """The palm searched in the frame of the posture's palm
        (:func:`~graspnet_torch.solver.search_space.palm_space_around`): a warm start from it is
        the zero pose, far from the angles' bounds (the problem's own frame may put it at rx = pi,
        where a bound stops it) and from the Euler angles' singularity; the contact fingers'
        joints within ``solver.polish.warm_step_deg`` of the posture's (:meth:`near`)."""

        R, t = pose_to_rt(posture.palm_pose.to(torch.float64))
        palm = np.eye(4)
        palm[:3, :3], palm[:3, 3] = R.numpy(), t.numpy()
        space = palm_space_around(robot, problem, palm)
        return cls(robot, problem, solver, ik, dtype, device, collisions, spaces=[space]).near(
            posture, solver.polish.warm_step_deg)

    def proposal_input(self) -> tuple[Tensor, Tensor]:
        """The contacts in each problem's contact search frame
        (:func:`~graspnet_torch.solver.search_space.contact_search_frame`, whatever its
        ``palm_bounds``: the same contacts moved and turned give the same input), one slot per
        robot finger: (R, F_all, 3), mask (R, F_all)."""

        targets, mask = super().proposal_input()  # in the search frame G of each row
        P_R, P_t = self._proposal_frames()  # the proposal frame P in G, per row
        local = untransform_points(P_R.unsqueeze(1), P_t.unsqueeze(1), targets.double()).float()
        return local * mask.unsqueeze(-1), mask

    def proposal_configs(self, configs: Tensor, rows: Tensor) -> Tensor:
        """Palm poses (B, K, 6) in the rows' proposal frames P -> in the search frame G (G^-1 P
        pose), each angle within 2 pi of the middle of its bounds."""

        B, K, _ = configs.shape
        P_R, P_t = (f[rows.cpu()] for f in self._proposal_frames())
        R, t = pose_to_rt(configs.double().reshape(B * K, 6))
        R, t = compose(P_R.repeat_interleave(K, 0), P_t.repeat_interleave(K, 0), R, t)
        pose = rt_to_pose(R, t).reshape(B, K, 6)
        lo, hi = (b.reshape(-1, 6)[rows.cpu() if b.dim() == 2 else 0] for b in self._bounds64)
        middle = ((lo[..., 3:] + hi[..., 3:]) / 2).reshape(-1, 1, 3).expand(B, 1, 3)
        pose[..., 3:] += 2 * math.pi * torch.round((middle - pose[..., 3:]) / (2 * math.pi))
        return pose.to(configs)

    def _proposal_frames(self) -> tuple[Tensor, Tensor]:
        """Per row of :meth:`proposal_input`: the proposal frame P in the search frame G
        (G^-1 C_p), rotation (R, 3, 3) and translation (R, 3), float64."""
        if self._proposal is None:

            frames = np.stack([np.eye(4) if s.kind == "contacts" else  # the search frame is the proposal frame
                               np.linalg.inv(s.frame) @ contact_search_frame(self.robot, p)
                               for p, s in zip(self.world_problems, self.spaces, strict=True)])
            if len(self.world_problems) > 1:
                frames = np.repeat(frames, self.runs, axis=0)
            frames = torch.as_tensor(frames, dtype=torch.float64)
            self._proposal = (frames[:, :3, :3], frames[:, :3, 3])
        return self._proposal

    def palm_frame(self, config: Tensor) -> tuple[Tensor, Tensor]:
        """The configuration's first 6 columns are the palm pose. (T, n) -> R (T, 3, 3), t (T, 3)."""
        return pose_to_rt(config[..., :6])

    def palm_frame_jacobian(self, config: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """(T, n) -> R (T, 3, 3), t (T, 3), J (T, 6, n) (:func:`~graspnet_torch.robot.transforms.pose_jacobian`;
        zero in the shared joints' columns: they do not move the palm)."""
        R, t, J = pose_jacobian(config[..., :6])
        if self.shared_slots:
            J = torch.cat([J, J.new_zeros(*J.shape[:-1], self.shared_slots)], dim=-1)
        return R, t, J

    def _exact_bounds(self) -> tuple[Tensor, Tensor]:
        return self._bounds64

    def _config_of(self, posture: Posture) -> Tensor:
        """The posture's palm pose in the (first) search frame G: G^-1 o pose (1, 6); each angle
        taken within 2 pi of the middle of its bounds."""


        R, t = pose_to_rt(posture.palm_pose.to(torch.float64).reshape(1, 6))
        G_R, G_t = (f[:1] for f in self.frame64)
        pose = rt_to_pose(G_R.transpose(-1, -2) @ R, ((t - G_t).unsqueeze(1) @ G_R).squeeze(1))
        lo, hi = (b.reshape(-1, self.n)[0] for b in self._bounds64)
        middle = (lo[3:6] + hi[3:6]) / 2
        pose[:, 3:] += 2 * math.pi * torch.round((middle - pose[:, 3:]) / (2 * math.pi))
        if self.shared_slots:  # the posture's shared joints (where it holds them: the robot's)
            shared = posture.shared if posture.shared is not None else torch.as_tensor(self.robot.shared_reference)
            pose = torch.cat([pose, shared.to(pose).reshape(1, -1)], dim=1)
        return pose

    @classmethod
    def check(cls, robot: Robot, problem: GraspProblem, solver: SolverCfg) -> None:
        """Refuse a contact that no palm pose within the bounds can bring a fingertip to: farther
        from the box of palm positions than the finger can reach (its base offset plus the lengths
        of its links, an upper bound whatever the joints); without bounds, contacts that no palm
        position reaches together (:func:`~graspnet_torch.solver.search_space.palm_search_space`).
        A robot with an arm is not a free hand."""
        if robot.has_body:
            raise ProblemError(f"{problem.source}: robot '{robot.name}' has an arm; this fits free hands")
        bounds = problem.bounds()
        if bounds is None:

            palm_search_space(robot, problem)
            return
        lo, hi = bounds.lower[:3], bounds.upper[:3]
        for contact, point in zip(problem.contacts, problem.contacts_world(), strict=True):
            reach = finger_reach_bound(robot, contact.finger)
            gap = float(np.linalg.norm(point - np.clip(point, lo, hi)))
            if gap > reach:
                raise ProblemError(f"{problem.source}: the {contact.finger} contact lies {gap:.3f} m from the palm's "
                                   f"search space but the {contact.finger} reaches at most {reach:.3f} m from the "
                                   f"palm")

    @classmethod
    def unreachable(cls, robot: Robot, problem: GraspProblem) -> list[str]:
        """The contact fingers whose contact lies farther from the box of palm positions than the
        finger's sampled reach (:func:`~graspnet_torch.solver.search_space.finger_reach`)."""

        if not problem.contacts:
            return []
        space = palm_search_space(robot, problem)
        G = space.frame
        local = (problem.contacts_world() - G[:3, 3]) @ G[:3, :3]
        gap = np.linalg.norm(local - np.clip(local, space.lower[:3], space.upper[:3]), axis=1)
        reach = finger_reach(robot)
        return [c.finger for c, g in zip(problem.contacts, gap, strict=True) if g > reach[robot.finger_index(c.finger)]]
