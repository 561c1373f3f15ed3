"""Random reachable grasp problems, one generator per robot kind: a posture drawn within the robot's
search space and limits gives the contacts (or, for a gripper, the object points), so a solution is
known to exist.

==============================  ==================================================================
:func:`random_hand_problem`     a free hand: the palm within ``palm_bounds`` (or anywhere turned)
:func:`random_arm_problem`      a hand on an arm: the arm's joints within their limits
:func:`random_reachable_problem`  either of the two, by ``robot.kind`` (``gt.random_reachable_problem``)
:func:`random_gripper_problems`   a two-point gripper (MANUS): its gripper points as object points
:func:`random_obstacle_problems`  a hand on an arm among random obstacles that clear the posture
==============================  ==================================================================

Each is deterministic in its seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["CONTACT_GENERATORS", "random_arm_problem", "random_gripper_problems", "random_hand_problem",
           "random_obstacle_problems", "random_reachable_problem"]


def _uniform(limits: tuple, g: torch.Generator) -> Tensor:
    lo, hi = (torch.as_tensor(a) for a in limits)
    return lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)


def _fingers_problem(robot: Robot, tips: Tensor, g: torch.Generator, seed: int,
                     n_fingers: int | Sequence[int] | None) -> GraspProblem:
    """``n_fingers`` fingers (a number, or a range ``(lo, hi)`` drawn uniformly; default 2 to all)
    chosen at random touch their fingertips ``tips`` (F, 3)."""
    lo_k, hi_k = (2, robot.n_fingers) if n_fingers is None else \
        (n_fingers, n_fingers) if isinstance(n_fingers, int) else tuple(n_fingers)
    k = int(torch.randint(lo_k, min(hi_k, robot.n_fingers) + 1, (1,), generator=g))
    chosen = sorted(torch.randperm(robot.n_fingers, generator=g)[:k].tolist())
    contacts = [{"finger": robot.finger_names[i], "position": tips[i].tolist()} for i in chosen]
    return GraspProblem.from_mapping({"robot": robot.name, "contacts": contacts}, robot_cfg=robot.cfg,
                                     source=f"random problem {seed} of {robot.name}")


def _finger_joints(robot: Robot, g: torch.Generator) -> Tensor:
    if not robot.n_fingers or robot.n_fingers < 2:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    return _uniform(robot.finger_limits, g)


def random_hand_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A free hand's problem whose contacts are the fingertips of a random posture: the palm pose
    uniform within the robot's ``palm_bounds`` (without them: at the origin, turned uniformly at
    random), every free finger joint uniform within its limits, ``n_fingers`` fingers (see
    :func:`random_reachable_problem`)."""
    if robot.has_body:
        raise ValueError(f"robot '{robot.name}' has an arm: use random_arm_problem")
    g = torch.Generator().manual_seed(seed)
    q = _finger_joints(robot, g)
    if robot.palm_bounds is not None:
        b = robot.palm_bounds
        lo, hi = torch.as_tensor(b.lower), torch.as_tensor(b.upper)
        pose = lo + (hi - lo) * torch.rand(6, generator=g, dtype=torch.float64)
    else:  # no box: the palm at the origin, turned uniformly at random
        import numpy as np

        from graspnet_torch.robot.transforms import matrix_to_pose
        from graspnet_torch.tasks.objects import random_pose

        rng = np.random.default_rng(int(torch.randint(2**31, (1,), generator=g)))
        pose = matrix_to_pose(torch.as_tensor(random_pose(rng, radius=0.0)))
    return _fingers_problem(robot, robot.fingertips_world(pose, q), g, seed, n_fingers)


def random_arm_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A hand on an arm: its problem whose contacts are the fingertips of a random posture: every
    arm joint and free finger joint uniform within its limits, ``n_fingers`` fingers (see
    :func:`random_reachable_problem`)."""
    if not robot.has_body:
        raise ValueError(f"robot '{robot.name}' has no arm: use random_hand_problem")
    g = torch.Generator().manual_seed(seed)
    q = _finger_joints(robot, g)
    body = _uniform(robot.body_limits, g)
    return _fingers_problem(robot, robot.fingertips_world_from_body(body, q), g, seed, n_fingers)


CONTACT_GENERATORS = {"hand": random_hand_problem, "arm_hand": random_arm_problem}
"""``robot.kind`` -> the generator of its contact problems (a gripper has none: see
:func:`random_gripper_problems`)."""


def random_reachable_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A problem whose contacts are the fingertips of a random posture of a robot with fingers: the
    generator of the robot's kind (``robot.kind``): :func:`random_hand_problem` for a free hand,
    :func:`random_arm_problem` for a hand on an arm.

    ``n_fingers`` fingers (a number, or a range ``(lo, hi)`` drawn uniformly; default 2 to all)
    chosen at random touch their fingertips. Deterministic in ``seed``.
    """
    generator = CONTACT_GENERATORS.get(robot.kind)
    if generator is None:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    return generator(robot, seed, n_fingers)


def random_gripper_problems(robot: Robot, n: int, seed: int = 11) -> list[GraspProblem]:
    """``n`` problems of a two-point gripper (MANUS): a random configuration (every body joint
    uniform within its limits) puts the gripper's two points, which become the object's two points
    (no object, no table; every other problem lists them in reverse order)."""
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    gen = torch.Generator().manual_seed(seed)
    problems = []
    for k in range(n):
        q = lo + (hi - lo) * torch.rand(1, len(lo), generator=gen, dtype=torch.float64)
        pts = robot.gripper_points(q)[0].tolist()
        if k % 2:
            pts = pts[::-1]
        problems.append(GraspProblem.from_mapping({"name": f"random{k}", "robot": robot.name, "points": pts},
                                                  f"<random {k}>"))
    return problems


def random_obstacle_problems(robot: Robot, n: int, seed: int = 7,
                             fingers: Sequence[str] = ("thumb", "index", "middle"),
                             anchors: Sequence[str] = ("shoulder_rotation_link", "elbow_flexion_link", "palm"),
                             ) -> list[GraspProblem]:
    """``n`` problems of a hand on an arm among obstacles: a random arm posture (the middle 60 % of
    every joint range) and ``fingers`` (the middle 60 % of their ranges) give the contacts; two or
    three obstacles (boxes, cylinders, spheres of 3-15 cm) are centred 12-20 cm from a point near
    one of the links ``anchors``, kept only if they clear that posture (FCL) and swallow no contact;
    the search space is +-30 deg about the posture, shifted by up to 10 deg."""
    import numpy as np

    from graspnet_torch.collision import CollisionScene
    from graspnet_torch.errors import ProblemError
    from graspnet_torch.robot.robot import Posture

    rng = np.random.default_rng(seed)
    lo, hi = (np.degrees(a) for a in robot.body_limits)
    flo, fhi = robot.finger_limits
    problems: list[GraspProblem] = []
    while len(problems) < n:
        qa = lo + (hi - lo) * rng.uniform(0.2, 0.8, lo.size)
        q = robot.home_posture().fingers.clone()
        for f in fingers:
            i = robot.finger_index(f)
            q[i] = torch.as_tensor(flo[i] + (fhi[i] - flo[i]) * rng.uniform(0.2, 0.8, flo[i].size))
        body = torch.as_tensor(np.radians(qa))
        tips = robot.fingertips_world_from_body(body, q)
        posture = Posture(palm_pose=torch.zeros(6), fingers=q, body=body)
        frames = robot.link_frames(posture)
        points = [frames[link][:3, 3] for link in anchors]
        obstacles = []
        for _ in range(rng.integers(2, 4)):
            a = points[rng.integers(len(points))] + rng.normal(0, 0.05, 3)
            direction = rng.normal(size=3)
            centre = a + direction / np.linalg.norm(direction) * rng.uniform(0.12, 0.2)
            kind = ("box", "cylinder", "sphere")[rng.integers(3)]
            size = {"box": rng.uniform(0.05, 0.15, 3).tolist(), "cylinder": [float(rng.uniform(0.02, 0.05)), 0.3],
                    "sphere": [float(rng.uniform(0.03, 0.07))]}[kind]
            obstacles.append({"shape": kind, "size": size, "pose": [*centre.tolist(), 0, 0, float(rng.uniform(0, 90))]})
        shift = rng.uniform(-10, 10, lo.size)
        data = {"robot": robot.name, "obstacles": obstacles,
                "contacts": [{"finger": f, "position": tips[robot.finger_index(f)].tolist()} for f in fingers],
                "bounds": {"min": np.maximum(qa + shift - 30, lo).tolist(),
                           "max": np.minimum(qa + shift + 30, hi).tolist()}}
        try:
            problem = GraspProblem.from_mapping(data, source=f"random-{len(problems)}", robot_cfg=robot.cfg)
        except ProblemError:  # an obstacle swallows a contact: draw again
            continue
        if CollisionScene(robot, problem).count(posture) > 0:
            continue  # an obstacle hits the posture that made the contacts: draw again
        problems.append(problem)
    return problems
