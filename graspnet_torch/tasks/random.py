"""Random reachable grasp problems: a posture drawn within the robot's search space and limits,
its fingertips taken as the contacts, so a solution is known to exist."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["random_reachable_problem"]


def random_reachable_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A problem whose contacts are the fingertips of a random posture.

    The palm pose is uniform within the robot's ``palm_bounds`` (a free hand; a hand without them:
    at the origin, any orientation) or the arm's joints within their limits (a hand on an arm);
    every free finger joint is uniform within its limits; ``n_fingers`` fingers (a number, or a
    range ``(lo, hi)`` drawn uniformly; default 2 to all) chosen at random touch their fingertips.
    Deterministic in ``seed``.
    """
    if not robot.n_fingers or robot.n_fingers < 2:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    g = torch.Generator().manual_seed(seed)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = flo + (fhi - flo) * torch.rand(flo.shape, generator=g, dtype=torch.float64)
    if robot.has_body:
        blo, bhi = (torch.as_tensor(a) for a in robot.body_limits)
        body = blo + (bhi - blo) * torch.rand(blo.shape, generator=g, dtype=torch.float64)
        tips = robot.fingertips_world_from_body(body, q)
    elif robot.palm_bounds is not None:
        b = robot.palm_bounds
        lo, hi = torch.as_tensor(b.lower), torch.as_tensor(b.upper)
        pose = lo + (hi - lo) * torch.rand(6, generator=g, dtype=torch.float64)
        tips = robot.fingertips_world(pose, q)
    else:  # no box: the palm at the origin, turned uniformly at random
        import numpy as np

        from graspnet_torch.robot.transforms import matrix_to_pose
        from graspnet_torch.tasks.objects import random_pose

        rng = np.random.default_rng(int(torch.randint(2**31, (1,), generator=g)))
        tips = robot.fingertips_world(matrix_to_pose(torch.as_tensor(random_pose(rng, radius=0.0))), q)
    lo_k, hi_k = (2, robot.n_fingers) if n_fingers is None else \
        (n_fingers, n_fingers) if isinstance(n_fingers, int) else tuple(n_fingers)
    k = int(torch.randint(lo_k, min(hi_k, robot.n_fingers) + 1, (1,), generator=g))
    chosen = sorted(torch.randperm(robot.n_fingers, generator=g)[:k].tolist())
    contacts = [{"finger": robot.finger_names[i], "position": tips[i].tolist()} for i in chosen]
    return GraspProblem.from_mapping({"robot": robot.name, "contacts": contacts}, robot_cfg=robot.cfg,
                                     source=f"random problem {seed} of {robot.name}")
