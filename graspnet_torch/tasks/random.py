"""Random reachable grasp problems, one generator per robot kind: a posture drawn within the robot's
search space and limits gives the contacts (or, for a gripper, the object points), so a solution is
known to exist.

================================  ================================================================
:func:`random_hand_problem`       a free hand: the palm within ``palm_bounds`` (or anywhere turned)
:func:`random_arm_problem`        a hand on an arm: the arm's joints within their limits
:func:`random_reachable_problem`  the generator of the robot's kind (``gt.random_reachable_problem``)
:func:`random_gripper_problems`   a two-point gripper (MANUS): its gripper points as object points
:func:`random_sequence`           frames of a smooth random walk of a posture (tracking, retargeting)
:func:`random_posed_problem`      a random posture and the problem it solves (proposal training)
================================  ================================================================

Which generator, walk space and posed problem a robot gets is its kind's row of :data:`PROBLEMS`.
Each is deterministic in its seed. Problems among obstacles that must clear their posture are made
where collisions are known (:mod:`graspnet_torch.collision.problems`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.transforms import matrix_to_pose, pose_to_degrees, pose_to_rt
from graspnet_torch.tasks.objects import random_pose
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.tasks.reference import reference_posture

__all__ = ["PROBLEMS", "KindProblems", "WalkSpace", "arm_walk_space", "hand_walk_space", "random_arm_problem",
           "random_gripper_problems", "random_hand_problem", "random_posed_fingers", "random_posed_gripper",
           "random_posed_problem", "random_reachable_problem", "random_sequence"]


def _uniform(limits: tuple, g: torch.Generator) -> Tensor:
    lo, hi = (torch.as_tensor(a) for a in limits)
    return lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)


def _choose_fingers(robot: Robot, g: torch.Generator, n_fingers: int | Sequence[int] | None) -> list[int]:
    """Indices of ``n_fingers`` fingers (a number, or a range ``(lo, hi)`` drawn uniformly; default 2
    to all) chosen at random, in finger order."""
    lo_k, hi_k = (2, robot.n_fingers) if n_fingers is None else \
        (n_fingers, n_fingers) if isinstance(n_fingers, int) else tuple(n_fingers)
    k = int(torch.randint(lo_k, min(hi_k, robot.n_fingers) + 1, (1,), generator=g))
    return sorted(torch.randperm(robot.n_fingers, generator=g)[:k].tolist())


def _fingers_problem(robot: Robot, tips: Tensor, g: torch.Generator, seed: int,
                     n_fingers: int | Sequence[int] | None) -> GraspProblem:
    """``n_fingers`` fingers (see :func:`_choose_fingers`) chosen at random touch their fingertips
    ``tips`` (F, 3)."""
    contacts = [{"finger": robot.finger_names[i], "position": tips[i].tolist()}
                for i in _choose_fingers(robot, g, n_fingers)]
    return GraspProblem.from_mapping({"robot": robot.name, "contacts": contacts}, robot_cfg=robot.cfg,
                                     source=f"random problem {seed} of {robot.name}")


def _finger_joints(robot: Robot, g: torch.Generator) -> Tensor:
    if not robot.n_fingers or robot.n_fingers < 2:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    return _uniform(robot.finger_limits, g)


def random_hand_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A free hand's problem whose contacts are the fingertips of a random posture: the palm pose
    uniform within the robot's ``palm_bounds`` (without them: at the origin, turned uniformly at
    random), every free finger joint uniform within its limits, the joints the fingers share
    (:attr:`Robot.shared`) too, ``n_fingers`` fingers (see :func:`random_reachable_problem`)."""
    _check_generator(robot, random_hand_problem)
    g = torch.Generator().manual_seed(seed)
    q = _finger_joints(robot, g)
    if robot.palm_bounds is not None:
        b = robot.palm_bounds
        lo, hi = torch.as_tensor(b.lower), torch.as_tensor(b.upper)
        pose = lo + (hi - lo) * torch.rand(6, generator=g, dtype=torch.float64)
    else:  # no box: the palm at the origin, turned uniformly at random
        import numpy as np

        rng = np.random.default_rng(int(torch.randint(2**31, (1,), generator=g)))
        pose = matrix_to_pose(torch.as_tensor(random_pose(rng, radius=0.0)))
    shared = _uniform((robot.shared.lower, robot.shared.upper), g) if robot.shared.n else None
    return _fingers_problem(robot, robot.fingertips_world(pose, q, shared), g, seed, n_fingers)


def random_arm_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A hand on an arm: its problem whose contacts are the fingertips of a random posture: every
    arm joint and free finger joint uniform within its limits, ``n_fingers`` fingers (see
    :func:`random_reachable_problem`)."""
    _check_generator(robot, random_arm_problem)
    g = torch.Generator().manual_seed(seed)
    q = _finger_joints(robot, g)
    body = _uniform(robot.body_limits, g)
    return _fingers_problem(robot, robot.fingertips_world_from_body(body, q), g, seed, n_fingers)


def random_reachable_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None) -> GraspProblem:
    """A problem whose contacts are the fingertips of a random posture of a robot with fingers: the
    generator of the robot's kind (its row's ``random_problem``): :func:`random_hand_problem` for a
    free hand, :func:`random_arm_problem` for a hand on an arm.

    ``n_fingers`` fingers (a number, or a range ``(lo, hi)`` drawn uniformly; default 2 to all)
    chosen at random touch their fingertips. Deterministic in ``seed``.
    """
    generator = PROBLEMS[robot.kind].random_problem
    if generator is None:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    return generator(robot, seed, n_fingers)


@dataclass(frozen=True)
class WalkSpace:
    """The box a posture walks in for :func:`random_sequence`: a posture is a flat vector ``x`` (d,).

    Attributes:
        lower, upper: (d,) float64 bounds (equal for a coordinate that never moves: finger padding).
        place: ``x`` (d,) -> the palm's rotation in the world (3, 3) and every fingertip (F, 3).
        reference: ``x`` (d,) -> the posture as a problem file's ``reference`` mapping (degrees).
    """

    lower: Tensor
    upper: Tensor
    place: Callable[[Tensor], tuple[Tensor, Tensor]]
    reference: Callable[[Tensor], dict]


def _finger_box(robot: Robot) -> tuple[Tensor, Tensor]:
    lo, hi = (torch.as_tensor(a, dtype=torch.float64).reshape(-1) for a in robot.finger_limits)
    return lo, hi


def hand_walk_space(robot: Robot) -> WalkSpace:
    """A free hand: ``x`` = palm pose (6: m, rad) within ``palm_bounds`` (without them: at the
    origin, any orientation), then the finger joints (F * n) within their limits."""
    shape = (robot.n_fingers, robot.joints_per_finger)
    if robot.palm_bounds is not None:
        plo, phi = (torch.as_tensor(a, dtype=torch.float64) for a in (robot.palm_bounds.lower, robot.palm_bounds.upper))
    else:
        phi = torch.tensor([0, 0, 0, math.pi, math.pi / 2, math.pi], dtype=torch.float64)
        plo = -phi
    flo, fhi = _finger_box(robot)

    def place(x: Tensor) -> tuple[Tensor, Tensor]:
        return pose_to_rt(x[:6])[0], robot.fingertips_world(x[:6], x[6:].reshape(shape))

    def reference(x: Tensor) -> dict:
        return {"palm_pose": pose_to_degrees(x[:6]).tolist(),
                "joints": robot.finger_joints_to_file(x[6:].reshape(shape))}

    return WalkSpace(torch.cat([plo, flo]), torch.cat([phi, fhi]), place, reference)


def arm_walk_space(robot: Robot) -> WalkSpace:
    """A hand on an arm: ``x`` = the arm's joints (m) within their limits, then the finger joints."""
    m, shape = len(robot.body_joint_names), (robot.n_fingers, robot.joints_per_finger)
    blo, bhi = (torch.as_tensor(a, dtype=torch.float64) for a in robot.body_limits)
    flo, fhi = _finger_box(robot)

    def place(x: Tensor) -> tuple[Tensor, Tensor]:
        return robot.palm_frame(x[:m])[0], robot.fingertips_world_from_body(x[:m], x[m:].reshape(shape))

    def reference(x: Tensor) -> dict:
        return {"arm_joints": robot.body_joints_to_file(x[:m]),
                "joints": robot.finger_joints_to_file(x[m:].reshape(shape))}

    return WalkSpace(torch.cat([blo, flo]), torch.cat([bhi, fhi]), place, reference)


def _turn_deg(R0: Tensor, R1: Tensor) -> float:
    """The angle (degrees) of the rotation from ``R0`` (3, 3) to ``R1`` (3, 3)."""
    c = (float(torch.trace(R0.T @ R1)) - 1) / 2
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def random_sequence(robot: Robot, seed: int, frames: int, n_fingers: int | Sequence[int] | None = None,
                    step_m: float = 0.01, step_deg: float = 5.0) -> list[GraspProblem]:
    """``frames`` problems along a smooth random walk of a posture (tracking, retargeting).

    The posture starts uniform in the robot's search space (its kind's ``walk_space``: a free
    hand's palm pose within ``palm_bounds`` and its finger joints within their limits; a hand on
    an arm: its arm and finger joints) and moves with some persistence of
    direction, reflected at the bounds. Every step is halved until each contact fingertip moves at
    most ``step_m`` (m) and the palm turns at most ``step_deg`` (degrees). The same ``n_fingers``
    fingers (see :func:`random_reachable_problem`) touch their fingertips in every frame; each
    problem carries the posture that made it as its ``reference``. Deterministic in ``seed``.
    """
    make_space = PROBLEMS[robot.kind].walk_space
    if make_space is None:
        raise ValueError(f"robot '{robot.name}' needs at least two fingers for a contact problem")
    if frames < 1 or step_m <= 0 or step_deg <= 0:
        raise ValueError(f"random_sequence needs frames >= 1 and positive steps, got frames={frames}, "
                         f"step_m={step_m}, step_deg={step_deg}")
    space = make_space(robot)
    span = space.upper - space.lower
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(span.shape, generator=g, dtype=torch.float64)  # the posture, 0..1 within the box
    chosen = _choose_fingers(robot, g, n_fingers)
    names = [robot.finger_names[i] for i in chosen]
    velocity = torch.zeros_like(u)
    R, tips = space.place(space.lower + span * u)
    problems = []
    for t in range(frames):
        if t:
            noise = torch.randn(u.shape, generator=g, dtype=torch.float64) * (span > 0)
            velocity = 0.8 * velocity + 0.6 * noise / noise.abs().max().clamp_min(1e-12)
            velocity = velocity / velocity.abs().max().clamp_min(1e-12)
            step = 0.1
            for _ in range(60):  # halved until both limits hold (2^-60: no move at all)
                moved = u + step * velocity
                folded = torch.remainder(moved, 2.0)
                new_u = torch.where(folded > 1, 2 - folded, folded)  # reflected at 0 and 1
                R1, tips1 = space.place(space.lower + span * new_u)
                far = float(torch.linalg.vector_norm(tips1[chosen] - tips[chosen], dim=-1).max())
                if far <= step_m and _turn_deg(R, R1) <= step_deg:
                    break
                step /= 2
            else:
                new_u, R1, tips1 = u, R, tips
            velocity = torch.where(torch.remainder(torch.floor(moved), 2) == 1, -velocity, velocity)
            u, R, tips = new_u, R1, tips1
        contacts = [{"finger": n, "position": tips[i].tolist()} for n, i in zip(names, chosen, strict=True)]
        data = {"robot": robot.name, "contacts": contacts, "reference": space.reference(space.lower + span * u)}
        problems.append(GraspProblem.from_mapping(data, robot_cfg=robot.cfg,
                                                  source=f"random sequence {seed} of {robot.name}, frame {t}"))
    return problems


def random_gripper_problems(robot: Robot, n: int, seed: int = 11) -> list[GraspProblem]:
    """``n`` problems of a two-point gripper (MANUS): a random configuration (every body joint
    uniform within its limits) puts the gripper's two points, which become the object's two points
    (no object, no table; every other problem lists them in reverse order)."""
    gen = torch.Generator().manual_seed(seed)
    problems = []
    for k in range(n):
        pts = robot.gripper_points(_uniform(robot.body_limits, gen)[None])[0].tolist()
        if k % 2:
            pts = pts[::-1]
        problems.append(GraspProblem.from_mapping({"name": f"random{k}", "robot": robot.name, "points": pts},
                                                  f"<random {k}>"))
    return problems


def random_posed_problem(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None
                         ) -> tuple[GraspProblem, Posture]:
    """A random posture of any robot and the problem it solves (what a posture proposal model
    learns from): its kind's ``posed_problem`` (:func:`random_posed_fingers`,
    :func:`random_posed_gripper`). Deterministic in ``seed``."""
    return PROBLEMS[robot.kind].posed_problem(robot, seed, n_fingers)


def random_posed_fingers(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None
                         ) -> tuple[GraspProblem, Posture]:
    """A robot with fingers: a posture uniform in its walk space (its kind's ``walk_space``: a free
    hand's palm within its search space, an arm's joints) with ``n_fingers`` contact fingers (see
    :func:`random_reachable_problem`), and the problem it solves."""
    problem = random_sequence(robot, seed, 1, n_fingers)[0]
    return problem, reference_posture(robot, problem)


def random_posed_gripper(robot: Robot, seed: int, n_fingers: int | Sequence[int] | None = None
                         ) -> tuple[GraspProblem, Posture]:
    """A two-point gripper: its body joints uniform within their limits and the two gripper points
    as the object's (in either order); ``n_fingers`` is unused."""
    g = torch.Generator().manual_seed(seed)
    q = _uniform(robot.body_limits, g)
    points = robot.gripper_points(q.unsqueeze(0))[0].tolist()
    if bool(torch.rand((), generator=g) < 0.5):
        points = points[::-1]
    problem = GraspProblem.from_mapping({"robot": robot.name, "points": points},
                                        source=f"random posed problem {seed} of {robot.name}")
    home = robot.home_posture(torch.float64)
    return problem, Posture(palm_pose=home.palm_pose, fingers=home.fingers, body=q)


def _check_generator(robot: Robot, generator: Callable) -> None:
    """Refuse a generator that is not the one of the robot's kind."""
    if PROBLEMS[robot.kind].random_problem is not generator:
        raise ValueError(f"robot '{robot.name}' ({robot.kind}): its random problems come from "
                         f"random_reachable_problem, not {generator.__name__}")


@dataclass(frozen=True)
class KindProblems:
    """A robot kind's random problems (one row of :data:`PROBLEMS`).

    Attributes:
        posed_problem: ``(robot, seed, n_fingers) -> (GraspProblem, Posture)``: a random posture
            and the problem it solves (what a posture proposal model learns from).
        random_problem: ``(robot, seed, n_fingers) -> GraspProblem``, a random reachable contact
            problem (:func:`random_reachable_problem`); None: the kind has no contacts.
        walk_space: ``Robot -> WalkSpace``: the box its posture walks in for
            :func:`random_sequence`; None: no sequences.
    """

    posed_problem: Callable[[Robot, int, int | Sequence[int] | None], tuple[GraspProblem, Posture]]
    random_problem: Callable[[Robot, int, int | Sequence[int] | None], GraspProblem] | None = None
    walk_space: Callable[[Robot], WalkSpace] | None = None


PROBLEMS: dict[str, KindProblems] = {
    "hand": KindProblems(random_posed_fingers, random_hand_problem, hand_walk_space),
    "arm_hand": KindProblems(random_posed_fingers, random_arm_problem, arm_walk_space),
    "gripper": KindProblems(random_posed_gripper),
}
"""Robot kind -> its random problems."""
