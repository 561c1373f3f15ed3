"""Where a free hand's palm is searched for: a space that follows the problem.

Without ``palm_bounds`` in the problem, the palm's search space is built from the contacts, so
that moving and turning a problem (object, contacts, obstacles) moves and turns the space, and
with it the grasp the solver finds:

- a *contact frame* C made from the contact points alone (:func:`contact_frame`): origin at their
  centroid, x from the first contact (the thumb's, in robot finger order) to the centroid of the
  others, z the oriented normal of the polygon they make in finger order (Newell's method), y = z
  x x. It is equivariant: moving the contacts by a rigid motion M moves C to M C. With two
  contacts, or contacts on a line, the rotation about x is fixed by a reference direction (the
  object's z axis, else the world's);
- the same frame made from the robot's own fingertips of those fingers at mid-range joints, H in
  the palm frame: the palm pose that lays the hand's frame onto the contacts' is G = C H^-1;
- the search frame is G; the palm pose is searched in it as (x, y, z, rx, ry, rz): any
  orientation (rx, rz in [-pi, pi], ry in [-pi/2, pi/2]; the centre, 0, is the aligned pose) and
  the positions from which every contact finger can reach its contact: the palm origin lies
  within a finger's reach (the farthest its fingertip gets from the palm origin, sampled over
  its joint range) of that finger's contact, so within the intersection of one box per contact.

A problem's explicit ``palm_bounds`` (a box in the world) or ``palm_bounds: robot`` (the robot
config's, the paper's Table 1 for ``hand``) are searched as given, in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.transforms import compose, pose_to_rt, rpy_to_matrix_np, rt_to_pose
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["PalmSearchSpace", "contact_frame", "contact_search_frame", "finger_reach", "finger_reach_bound",
           "gripper_bounds", "hand_frame", "palm_search_space", "palm_space_around", "sample_hand_configurations"]

ORIENTATIONS = (np.array([-math.pi, -math.pi / 2, -math.pi]), np.array([math.pi, math.pi / 2, math.pi]))
REACH_SAMPLES = 4096
REACH_MARGIN = 0.002  # m added to a finger's sampled reach


@dataclass(frozen=True)
class PalmSearchSpace:
    """A palm search space: a box of poses in a frame.

    Attributes:
        frame: (4, 4) float64, the search frame in the world (identity for a box in the world).
        lower, upper: (6,) float64, the palm pose bounds in that frame (m, rad).
        kind: 'contacts' (built from the contacts), 'problem' (the problem's box), 'robot'
            (the robot config's box) or 'start' (around a given palm pose: a warm start).
    """

    frame: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    kind: str


def contact_frame(points: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """A frame made from contact points, equivariant under rigid motions (module docstring).

    Args:
        points: (K, 3) K >= 2 points, the first the thumb's (robot finger order).
        reference: (3,) a direction that fixes the rotation about x when the points are (nearly)
            on a line; default the world's z (then x).
    Returns:
        (4, 4) float64.
    """
    p = np.asarray(points, dtype=np.float64)
    centre = p.mean(0)
    x = p[0] - p[1:].mean(0)
    if np.linalg.norm(x) < 1e-9:  # the thumb at the others' centroid: any direction through the points
        x = p[1] - p[0]
    x = x / np.linalg.norm(x)
    d = p - centre  # Newell: the polygon's area-weighted normal, oriented by the finger order
    normal = _cross(d, np.roll(d, -1, axis=0)).sum(0)
    z = normal - (normal @ x) * x
    if np.linalg.norm(z) < 1e-6 * max(1.0, float(np.abs(p - centre).max()) ** 2):  # on a line
        for ref in ([] if reference is None else [np.asarray(reference, dtype=np.float64)]) + [np.eye(3)[2],
                                                                                               np.eye(3)[0]]:
            z = ref - (ref @ x) * x
            if np.linalg.norm(z) > 1e-6:
                break
    z = z / np.linalg.norm(z)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, _cross(z, x), z, centre
    return T


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of (..., 3) arrays (np.cross costs ~40 us on three points, this ~5: it runs per problem)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


@lru_cache(maxsize=64)
def _reach_and_mid(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Per finger: the farthest its fingertip gets from the palm origin (sampled over the joint
    range, plus a margin; at most the bound of its link lengths) and its fingertip at mid-range
    joints, in the palm frame: (F,), (F, 3)."""
    g = torch.Generator().manual_seed(0)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = lo + (hi - lo) * torch.rand(REACH_SAMPLES, *lo.shape, generator=g, dtype=torch.float64)
    q = torch.cat([q, lo.unsqueeze(0), hi.unsqueeze(0)])
    far = robot.fingertips_palm(q).norm(dim=-1).amax(0).numpy() + REACH_MARGIN
    bound = np.array([finger_reach_bound(robot, f) for f in robot.finger_names])
    mid = robot.fingertips_palm((lo + hi) / 2).numpy()
    return np.minimum(far, bound), mid


def finger_reach(robot: Robot) -> np.ndarray:
    """(F,) the farthest each finger's tip gets from the palm origin, metres (sampled, + 2 mm)."""
    return _reach_and_mid(robot)[0]


@lru_cache(maxsize=256)
def hand_frame(robot: Robot, fingers: tuple[str, ...]) -> np.ndarray:
    """(4, 4) :func:`contact_frame` of the robot's own fingertips of ``fingers`` (robot order) at
    mid-range joints, in the palm frame."""
    mid = _reach_and_mid(robot)[1]
    order = [robot.finger_index(f) for f in robot.finger_names if f in fingers]
    frame = contact_frame(mid[order], np.array([0.0, 0.0, 1.0]))
    frame.setflags(write=False)  # kept per robot and fingers (lru_cache): shared, so read-only
    return frame


@lru_cache(maxsize=256)
def _hand_frame_inverse(robot: Robot, fingers: tuple[str, ...]) -> np.ndarray:
    """(4, 4) the inverse of :func:`hand_frame` (a rigid motion), kept per robot and fingers."""
    H = hand_frame(robot, fingers)
    inv = np.eye(4)
    inv[:3, :3] = H[:3, :3].T
    inv[:3, 3] = -H[:3, :3].T @ H[:3, 3]
    inv.setflags(write=False)
    return inv


def palm_search_space(robot: Robot, problem: GraspProblem) -> PalmSearchSpace:
    """The palm search space of a free-hand problem (module docstring). Refuses (ProblemError) a
    problem whose contacts no palm position can reach together."""
    box = problem.bounds()
    if box is not None:
        return PalmSearchSpace(np.eye(4), box.lower.copy(), box.upper.copy(),
                               "robot" if problem.palm_bounds == "robot" else "problem")
    fingers, world = _ordered_contacts(robot, problem)
    G = contact_search_frame(robot, problem)
    lo, hi = _reach_box(robot, problem, fingers, world, G)
    return PalmSearchSpace(G, np.concatenate([lo, ORIENTATIONS[0]]), np.concatenate([hi, ORIENTATIONS[1]]),
                           "contacts")


def contact_search_frame(robot: Robot, problem: GraspProblem) -> np.ndarray:
    """(4, 4) the search frame G = C H^-1 made from a problem's contacts (module docstring),
    whatever its ``palm_bounds``: where a posture proposal model sees the contacts and answers."""
    fingers, world = _ordered_contacts(robot, problem)
    reference = None
    if problem.object is not None:
        reference = rpy_to_matrix_np(problem.object.pose[3:])[:, 2]
    return contact_frame(world, reference) @ _hand_frame_inverse(robot, fingers)


def palm_space_around(robot: Robot, problem: GraspProblem, palm: np.ndarray) -> PalmSearchSpace:
    """The palm search space of a warm start from a palm pose ``palm`` (4, 4) in the world: that
    pose is the frame (the start is the zero pose, far from the angles' bounds and from the
    Euler angles' singularity at ry = +-pi/2), any orientation, the positions from which every
    contact finger reaches its contact (a box in that frame, as :func:`palm_search_space`'s).
    A problem's explicit ``palm_bounds`` stay its space."""
    if problem.bounds() is not None:
        return palm_search_space(robot, problem)
    fingers, world = _ordered_contacts(robot, problem)
    G = np.asarray(palm, dtype=np.float64)
    lo, hi = _reach_box(robot, problem, fingers, world, G)
    return PalmSearchSpace(G, np.concatenate([lo, ORIENTATIONS[0]]), np.concatenate([hi, ORIENTATIONS[1]]), "start")


def _ordered_contacts(robot: Robot, problem: GraspProblem) -> tuple[tuple[str, ...], np.ndarray]:
    """The contact fingers in robot order and their contacts in the world (K, 3)."""
    order = [k for f in robot.finger_names for k, c in enumerate(problem.contacts) if c.finger == f]
    return tuple(problem.contacts[k].finger for k in order), problem.contacts_world()[order]


def _reach_box(robot: Robot, problem: GraspProblem, fingers: tuple[str, ...], world: np.ndarray, G: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The box (lower, upper (3,)) in the frame G of the palm positions from which each finger
    reaches its contact ``world`` (K, 3): the intersection of one box per contact. Refuses
    (ProblemError) contacts that no palm position reaches together."""
    local = (world - G[:3, 3]) @ G[:3, :3]  # the contacts in the frame G
    reach = finger_reach(robot)[[robot.finger_index(f) for f in fingers]]
    lo = (local - reach[:, None]).max(0)
    hi = (local + reach[:, None]).min(0)
    if np.any(lo > hi):
        far = np.linalg.norm(world[:, None] - world[None], axis=-1)
        i, j = np.unravel_index(np.argmax(far - reach[:, None] - reach[None]), far.shape)
        raise ProblemError(f"{problem.source}: the {fingers[i]} and {fingers[j]} contacts lie {far[i, j]:.3f} m apart "
                           f"but those fingertips reach at most {reach[i] + reach[j]:.3f} m apart (no palm position "
                           f"reaches both)")
    return lo, hi


def sample_hand_configurations(robot: Robot, space: PalmSearchSpace, n: int,
                               generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """n configurations uniform in a search space: palm poses uniform in its box (in its frame) and
    every finger joint uniform within its limits, float64.

    Returns:
        palm_pose: (n, 6) in the world (x, y, z, rx, ry, rz; m, rad); fingers: (n, F, J).
    """
    lo, hi = torch.as_tensor(space.lower), torch.as_tensor(space.upper)
    local = lo + (hi - lo) * torch.rand(n, 6, generator=generator, dtype=torch.float64)
    G = torch.as_tensor(space.frame)
    pose = rt_to_pose(*compose(G[:3, :3], G[:3, 3], *pose_to_rt(local)))
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = flo + (fhi - flo) * torch.rand(n, *flo.shape, generator=generator, dtype=torch.float64)
    return pose, q


def finger_reach_bound(robot: Robot, finger: str) -> float:
    """Upper bound of a fingertip's distance from the palm origin, whatever the joints: its base
    offset, the lengths of its links and the travel of its prismatic joints."""
    f = robot.fingers[finger]
    spec = f.chain.spec
    travel = sum(max(abs(lo), abs(hi)) for lo, hi, t in zip(spec.lower, spec.upper, spec.joint_types, strict=True)
                 if t == "prismatic")
    return float(np.linalg.norm(f.base_in_palm[:3, 3]) + np.linalg.norm(spec.offsets[:, :3, 3], axis=1).sum() + travel)


def gripper_bounds(robot: Robot, problem: GraspProblem, approach_m: float = 0.2,
                   approach_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """(n,) bounds of the body joints (m / rad): the joint limits, or +- (approach_m, approach_deg)
    about the problem's ``approach`` within them (joints the approach leaves out: their limits)."""
    lower, upper = (a.copy() for a in robot.body_limits)
    if problem.approach is None:
        return lower, upper
    names = robot.body_joint_names
    unknown = sorted(set(problem.approach) - set(names))
    if unknown:
        raise ProblemError(f"{problem.source}: approach: unknown joint(s) {', '.join(unknown[:5])} of robot "
                           f"'{robot.name}' (joints: {', '.join(names)})")
    for k, (name, kind) in enumerate(zip(names, robot.body.joint_types, strict=True)):
        if name not in problem.approach:
            continue
        value = problem.approach[name] * (math.pi / 180 if kind == "revolute" else 1.0)
        if not lower[k] - 1e-9 <= value <= upper[k] + 1e-9:
            unit = "degrees" if kind == "revolute" else "m"
            scale = 180 / math.pi if kind == "revolute" else 1.0
            raise ProblemError(f"{problem.source}: approach.{name}: {problem.approach[name]:g} lies outside its "
                               f"limits [{lower[k] * scale:.4g}, {upper[k] * scale:.4g}] {unit}")
        half = math.radians(approach_deg) if kind == "revolute" else approach_m
        lower[k], upper[k] = max(lower[k], value - half), min(upper[k], value + half)
    return lower, upper
