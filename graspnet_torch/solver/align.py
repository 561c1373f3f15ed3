"""Turning the pads toward the object (the surface contact model): a reported grasp whose pads
touch their contacts but face away from the object moved, palm (or arm) and contact fingers
together, until every pad normal lies within the cone, its tip kept on its target.

One Levenberg-Marquardt (:func:`~graspnet_torch.least_squares.levenberg_marquardt`) over the
whole configuration x = (the head's values: a free palm's pose or the body joints; the contact
fingers' free joints), with the residuals

    tip_i(x) - target_i                                   (3 per contact finger, metres)
    w max(0, |R_i(x) n_i + n_obj,i| - c)  (R_i n_i + n_obj,i) / |R_i n_i + n_obj,i|

(R_i: finger i's tip frame, n_i: its pad normal, n_obj,i: the object's outward normal at the
contact; c = 2 sin(theta / 2) for theta = :data:`ALIGN_MARGIN` of the cone: inside it, no pull) and
a forward-difference Jacobian of the link frames (the robot's kernel). The palm moves within
:data:`WINDOW_M` / :data:`WINDOW_DEG` of the grasp's, every joint within its limits; the caller
re-checks the result (FCL, the cone, the tolerance).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.surface import surface_normals
from graspnet_torch.least_squares import levenberg_marquardt, numerical_jacobian
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.contact import tip_targets
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ALIGN_MARGIN", "ALIGN_STEPS", "ALIGN_WEIGHT", "WINDOW_DEG", "WINDOW_M", "align_pads"]

ALIGN_STEPS = 40  # Levenberg-Marquardt steps
ALIGN_WEIGHT = 0.05  # metres per unit of |R n + n_obj| beyond the margin: a turned pad weighs as much as a far tip
ALIGN_MARGIN = 0.7  # the pull starts at this share of the cone
WINDOW_M, WINDOW_DEG = 0.03, 45.0  # how far the palm may move and turn from the grasp's


def align_pads(robot: Robot, problem: GraspProblem, posture: Posture, solver: SolverCfg) -> Posture:
    """The posture moved so that every contact finger's pad faces into the object (module
    docstring); the fingers without a contact, the shared joints and (a free hand) nothing else
    change. float64, on the CPU."""
    fingers = list(problem.fingers)
    rows = [robot.finger_index(f) for f in fingers]
    targets = torch.as_tensor(tip_targets(robot, problem, "surface"))  # (k, 3)
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    outward = torch.as_tensor(surface_normals(problem.object, contacts))  # (k, 3)
    pads = robot.pads
    normals = torch.as_tensor(np.stack([pads[f].normal for f in fingers]))  # (k, 3), tip frames
    offsets = torch.as_tensor(np.stack([np.zeros(3) if robot.cfg.fingers[f].tip_offset is None else
                                        np.asarray(robot.cfg.fingers[f].tip_offset, dtype=np.float64)
                                        for f in fingers]))
    head = robot.head
    h0 = head.values(posture).to(torch.float64)
    mask = torch.as_tensor(robot.finger_mask)
    free = mask[rows]  # (k, j): the contact fingers' free joints
    q0 = posture.fingers.to(torch.float64)
    x0 = torch.cat([h0, q0[rows][free]])
    n_h = h0.shape[0]
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    if head.anchored:
        hlo, hhi = (torch.as_tensor(a) for a in (head.lower, head.upper))
    else:
        window = torch.tensor([WINDOW_M] * 3 + [math.radians(WINDOW_DEG)] * 3, dtype=torch.float64)
        hlo, hhi = h0 - window, h0 + window
    lo = torch.cat([hlo, flo[rows][free]])
    hi = torch.cat([hhi, fhi[rows][free]])
    margin = 2 * math.sin(math.radians(solver.normal_cone_deg * ALIGN_MARGIN) / 2)
    names = None
    tip_links = [robot.cfg.fingers[f].tip for f in fingers]

    def postures(x: Tensor) -> tuple[Tensor, Tensor]:
        q = q0.expand(x.shape[0], -1, -1).clone()
        part = q[:, rows]
        part[:, free] = x[:, n_h:]
        q[:, rows] = part
        return x[:, :n_h], q

    def residual(x: Tensor) -> Tensor:
        nonlocal names
        h, q = postures(x)
        link_names, frames = head.link_frames(h, q)
        if names is None:
            names = [link_names.index(t) for t in tip_links]
        T = torch.as_tensor(frames[:, names])  # (B, k, 4, 4)
        R, t = T[..., :3, :3], T[..., :3, 3] + (T[..., :3, :3] @ offsets.unsqueeze(-1)).squeeze(-1)
        miss = (R @ normals.unsqueeze(-1)).squeeze(-1) + outward  # (B, k, 3): zero when the pad faces in
        size = miss.norm(dim=-1, keepdim=True)
        pull = ALIGN_WEIGHT * (size - margin).clamp_min(0) * miss / size.clamp_min(1e-12)
        return torch.cat([(t - targets).flatten(1), pull.flatten(1)], 1)

    def model(x: Tensor, _rows: Tensor) -> tuple[Tensor, Tensor]:
        return residual(x), numerical_jacobian(residual, x)

    goal = torch.zeros(6 * len(fingers), dtype=torch.float64)
    x = levenberg_marquardt(model, goal, x0[None], lo, hi, ALIGN_STEPS, tol=1e-6).x
    h, q = postures(x)
    return head.postures(h, q)[0]
