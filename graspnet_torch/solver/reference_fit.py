"""A posture that reaches every contact, found by bounded least squares (scipy), for tasks.

Used to design the shipped tasks and to show they are reachable: over the palm pose (within the
problem's palm search space: its box, or the one built from its contacts) and the contact
fingers' joints (within limits), minimise the fingertip-to-contact distances, with a small pull
of the joints towards mid-range so the posture looks like a hand (the pull is weak enough that an
exact solution, when one exists, is still found). Random restarts; float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import compose, pose_to_rt, rt_to_pose
from graspnet_torch.solver.search_space import palm_search_space
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["ReferenceFit", "find_reference_posture"]


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
                           joint_pull: float = 1e-3, center_pull: float = 1e-3) -> ReferenceFit:
    """Best of ``restarts`` bounded least-squares fits (see module docstring)."""
    from scipy.optimize import least_squares

    space = palm_search_space(robot, problem)  # the problem's box, or the one built from its contacts (a frame)
    G = torch.as_tensor(space.frame, dtype=torch.float64)
    idx = [robot.finger_index(f) for f in problem.fingers]
    flo, fhi = robot.finger_limits
    lo = np.concatenate([space.lower, flo[idx].ravel()])
    hi = np.concatenate([space.upper, fhi[idx].ravel()])
    hi = np.maximum(hi, lo + 1e-9)  # a pinned coordinate (min = max): least squares needs lo < hi
    mid = (flo[idx] + fhi[idx]).ravel() / 2
    pose_mid, pose_half = (space.lower + space.upper) / 2, np.maximum((space.upper - space.lower) / 2, 1e-9)
    contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)
    home = robot.home_posture(torch.float64).fingers
    F, n = len(idx), robot.joints_per_finger

    def world(x: np.ndarray) -> torch.Tensor:  # the palm pose in the world: G o (the pose in the search frame)
        return rt_to_pose(*compose(G[:3, :3], G[:3, 3], *pose_to_rt(torch.as_tensor(x[:6], dtype=torch.float64))))

    def tips(x: np.ndarray) -> torch.Tensor:
        q = home.clone()
        q[idx] = torch.as_tensor(x[6:], dtype=torch.float64).view(F, n)
        return robot.fingertips_world(world(x), q)[idx]

    def residual(x: np.ndarray) -> np.ndarray:
        r = (tips(x) - contacts).reshape(-1).numpy()
        return np.concatenate([r, joint_pull * (x[6:] - mid), center_pull * (x[:6] - pose_mid) / pose_half])

    rng = np.random.default_rng(seed)
    best = None
    for _ in range(restarts):
        x0 = lo + (hi - lo) * rng.uniform(0.1, 0.9, size=lo.shape)
        fit = least_squares(residual, x0, bounds=(lo, hi), xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)
        err = float(torch.linalg.vector_norm(tips(fit.x) - contacts, dim=-1).sum())
        if best is None or err < best[0]:
            best = (err, fit.x)
    x = best[1]
    errs = torch.linalg.vector_norm(tips(x) - contacts, dim=-1)
    return ReferenceFit(palm_pose=world(x).numpy(),
                        joints={f: x[6 + k * n: 6 + (k + 1) * n].copy() for k, f in enumerate(problem.fingers)},
                        errors={f: float(errs[k]) for k, f in enumerate(problem.fingers)})
