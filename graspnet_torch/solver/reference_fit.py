"""A posture that reaches every contact, found by bounded least squares, for tasks.

Used to design the shipped tasks and to show they are reachable: over the palm pose (within the
problem's palm search space: its box, or the one built from its contacts) and the contact
fingers' joints (within limits), minimise the fingertip-to-contact distances, with a small pull
of the joints towards mid-range so the posture looks like a hand (the pull is weak enough that an
exact solution, when one exists, is still found). The fingertips' residual, with the pulls as
the prior toward a posture, is handed to the package's one Levenberg-Marquardt
(:func:`~graspnet_torch.least_squares.levenberg_marquardt`; Jacobian by forward differences,
:func:`~graspnet_torch.least_squares.numerical_jacobian`), every random restart a row of one
batch; float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from graspnet_torch.least_squares import Prior, levenberg_marquardt, numerical_jacobian
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import compose, pose_to_rt, rt_to_pose
from graspnet_torch.solver.search_space import palm_search_space
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ReferenceFit", "find_reference_posture"]

FIT_ITERATIONS = 400  # Levenberg-Marquardt steps per restart at most (scipy's fit had 400 evaluations)


@dataclass
class ReferenceFit:
    """palm_pose: (6,) m/rad; joints: finger -> (n,) rad; errors: finger -> m."""

    palm_pose: np.ndarray
    joints: dict[str, np.ndarray]
    errors: dict[str, float]

    @property
    def total(self) -> float:
        return float(sum(self.errors.values()))


def find_reference_posture(robot: Robot, problem: GraspProblem, restarts: int = 24, seed: int = 0,
                           joint_pull: float = 1e-3, center_pull: float = 1e-3,
                           iterations: int = FIT_ITERATIONS) -> ReferenceFit:
    """Best of ``restarts`` bounded least-squares fits (see module docstring), at most
    ``iterations`` Levenberg-Marquardt steps each; the best: the least summed fingertip distance."""
    space = palm_search_space(robot, problem)  # the problem's box, or the one built from its contacts (a frame)
    G = torch.as_tensor(space.frame, dtype=torch.float64)
    idx = [robot.finger_index(f) for f in problem.fingers]
    flo, fhi = robot.finger_limits
    lo = np.concatenate([space.lower, flo[idx].ravel()])
    hi = np.concatenate([space.upper, fhi[idx].ravel()])
    mid = (flo[idx] + fhi[idx]).ravel() / 2
    pose_mid, pose_half = (space.lower + space.upper) / 2, np.maximum((space.upper - space.lower) / 2, 1e-9)
    contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)  # (C, 3)
    home = robot.home_posture(torch.float64).fingers
    F, n = len(idx), robot.joints_per_finger

    def world(x: torch.Tensor) -> torch.Tensor:  # (b, 6 + F n) -> the palm poses (b, 6) in the world: G o x[:, :6]
        return rt_to_pose(*compose(G[:3, :3], G[:3, 3], *pose_to_rt(x[:, :6])))

    def tips(x: torch.Tensor) -> torch.Tensor:  # (b, 6 + F n) -> the contact fingers' tips (b, C, 3)
        q = home.expand(x.shape[0], *home.shape).clone()
        q[:, idx] = x[:, 6:].reshape(-1, F, n)
        return robot.fingertips_world(world(x), q)[:, idx]

    def residual(x: torch.Tensor, rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return tips(x).flatten(1), numerical_jacobian(lambda y: tips(y).flatten(1), x)

    rng = np.random.default_rng(seed)
    x0 = torch.as_tensor(lo + (hi - lo) * rng.uniform(0.1, 0.9, size=(restarts, lo.size)))
    lo_t, hi_t = torch.as_tensor(lo), torch.as_tensor(hi)
    centre = torch.as_tensor(np.concatenate([pose_mid, mid]))
    weight = torch.as_tensor(np.concatenate([center_pull / pose_half, np.full(mid.size, joint_pull)]))
    fit = levenberg_marquardt(residual, contacts.reshape(-1), x0, lo_t, hi_t, iterations, prior=Prior(centre, weight))
    errs = torch.linalg.vector_norm(tips(fit.x) - contacts, dim=-1)  # (R, C)
    best = int(torch.argmin(errs.sum(1)))
    x = fit.x[best].numpy()
    return ReferenceFit(palm_pose=world(fit.x[best:best + 1])[0].numpy(),
                        joints={f: x[6 + k * n: 6 + (k + 1) * n].copy() for k, f in enumerate(problem.fingers)},
                        errors={f: float(errs[best, k]) for k, f in enumerate(problem.fingers)})
