"""Contact sets a hand can touch with its pads: sampled hand postures whose chosen fingers' pads
rest on the object's surface, facing into it.

One candidate is made in three steps (every candidate of a call in one batch):

1. *Palm*: a uniformly random palm orientation; the object is put in front of the palm (the palm
   collision box's thinnest axis, on the fingers' side) at a random point of the plane of the
   palm within the fingertips' reach, and at a random gap (``GAP_M``) from the palm's face, i.e.
   the palm looks at the object from a random direction, at a random roll.
2. *Fingers*: each finger closes along a random straight line in joint space that moves its pad
   forward, along the pad normal, whichever side of the finger the pad is on (a thumb's pad facing
   the fingers, not its flexion side): at the finger's open posture (``OPEN``: a random fraction
   of each joint's range above its lower limit) the tip's Jacobian column of each joint, dotted
   with the pad normal (both in the palm frame), says which way that joint pushes the pad. A joint
   pushing it forward (cosine at least ``FORWARD``) runs from ``OPEN`` up to ``CLOSE`` (fractions
   above its lower limit), one pushing it back runs the mirror image (fractions below its upper
   limit: from high to low), and one moving the pad sideways is held at a random fraction
   (``HOLD``) of its range all along the line. ``STEPS`` samples of the line, then bisection,
   find where its pad sphere (the tip frame's origin, radius the pad's depth) first touches the
   surface (distance = depth, by :func:`~graspnet_torch.collision.surface.surface_distance_near`:
   for a mesh within 0.58 mm of the exact distance, which the check of step 3 uses). A chosen finger
   stops there; a finger that is not chosen stops one sample short of touching (or closed). Of
   ``LINES`` lines per finger, a random one that touches within the cone (its touch point on the
   surface, see step 3) with its links clear of the object is kept, the first chosen finger's (the
   thumb's) the one whose inward normal best opposes the others' mean (force closure needs
   opposition).
3. *Check*: kept where every chosen finger touches (its pad within ``TOUCH_M`` of the surface),
   every pad normal (the tip rotation times the pad normal) lies within ``cone_deg`` of the inward
   normal at its touch point, and no link lies deeper than ``penetration_m`` in the object nor two
   fingers through each other (the surface model's FCL scene).

The contact is the touch point: the pad sphere's point nearest the surface. Everything is drawn
from one ``numpy`` generator seeded by ``seed``: the same call gives the same sets.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.collision.spheres import shape_spheres
from graspnet_torch.collision.surface import surface_distance, surface_distance_near, surface_normals, touch_points
from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import grasp_quality
from graspnet_torch.robot.geometry import link_shapes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose_np, pose_to_matrix_np
from graspnet_torch.solver.contact import tip_frames
from graspnet_torch.synthesis.closing import close_lines, closing_lines
from graspnet_torch.tasks.auto_contacts import contact_fingers
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["FRICTION", "GAP_M", "OPPOSE", "TOUCH_M", "ContactSet", "check_pad_fingers", "opposes", "pad_contact_sets",
           "placeholder_problem"]

GAP_M = (0.0, 0.035)  # the object's gap to the palm's face
TOUCH_M = 1e-3  # a pad touches within this of the surface
BATCH = 64  # palm poses drawn at once
LINES = 16  # closing lines tried per finger and palm pose
OPPOSE = -0.3  # "opposed": the thumb's inward normal dotted with the others' mean lies below this
FRICTION = 0.6  # the friction grasp quality and "force_closure" are measured with (the physics check's too)


@dataclass(frozen=True)
class ContactSet:
    """A contact set the hand touches with its pads.

    Attributes:
        fingers: the k chosen fingers.
        contacts: (k, 3) the touch points, world.
        normals: (k, 3) the object's inward unit normals there.
        posture: the hand posture that touches them.
        angles_deg: (k,) each pad normal's angle to its inward normal.
    """

    fingers: tuple[str, ...]
    contacts: np.ndarray
    normals: np.ndarray
    posture: Posture
    angles_deg: np.ndarray

    def __iter__(self):  # unpacks as (contacts, normals, posture)
        return iter((self.contacts, self.normals, self.posture))


def placeholder_problem(robot: Robot, obj: Shape, fingers: Sequence[str], contacts: np.ndarray | None = None
                        ) -> GraspProblem:
    """A problem of ``robot`` holding ``obj`` (contacts: (k, 3) world, default the object's centre)."""
    T = np.eye(4)
    T[:3, :3] = _rotation(obj)
    T[:3, 3] = obj.pose[:3]
    pts = np.tile(obj.pose[:3], (len(fingers), 1)) if contacts is None else np.asarray(contacts).reshape(-1, 3)
    local = (pts - T[:3, 3]) @ T[:3, :3]
    data = {"robot": robot.cfg.name, "object": obj.to_mapping(),
            "contacts": [{"finger": f, "position": p.tolist()} for f, p in zip(fingers, local, strict=True)]}
    return GraspProblem.from_mapping(data, robot_cfg=robot.cfg, allow_outside_paths=True)


def _rotation(obj: Shape) -> np.ndarray:
    """(3, 3) a shape's rotation."""
    return pose_to_matrix_np(obj.pose)[:3, :3]


def _palm_front(robot: Robot) -> tuple[np.ndarray, float]:
    """The palm's front axis (palm frame, unit) and its face's offset along it (m): the palm
    collision box's thinnest axis, on the side of the home fingertips (no box: +y, 0)."""
    home = robot.home_posture()
    tips = robot.fingertips_palm(home.fingers).numpy().mean(axis=0)
    box = next((s.shape for s in link_shapes(robot.urdf) if s.link == robot.cfg.palm_link and s.shape.kind == "box"),
               None)
    if box is None:
        return np.array([0.0, 1.0, 0.0]), 0.0
    R = _rotation(box)
    axis = int(np.argmin(box.size))
    front = R[:, axis] * (1.0 if R[:, axis] @ (tips - box.pose[:3]) >= 0 else -1.0)
    return front, float(front @ box.pose[:3] + box.size[axis] / 2)


def _support(vertices: np.ndarray, centre: np.ndarray, d: np.ndarray) -> np.ndarray:
    """How far the object reaches from its centre along directions d (B, 3): (B,)."""
    return ((vertices - centre) @ d.T).max(axis=0)


def _finger_spheres(robot: Robot) -> list[tuple[int, str, np.ndarray, np.ndarray]]:
    """Every finger link's collision shapes as spheres: (finger row, link, centres (s, 3) in the
    link frame, radii (s,)) (:func:`~graspnet_torch.collision.spheres.shape_spheres`)."""
    owner = {}
    for i, finger in enumerate(robot.fingers.values()):
        for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip):
            owner[joint.child] = i
    out = []
    for shape in link_shapes(robot.urdf):
        if shape.link in owner:
            centres, radii = shape_spheres(shape)
            out.append((owner[shape.link], shape.link, centres, radii))
    return out


def _clearance(obj: Shape, names: list[str], frames: np.ndarray,
               spheres: list[tuple[int, str, np.ndarray, np.ndarray]]) -> np.ndarray:
    """(N, F) each finger's least clearance (m, negative: how deep) from the object, its links as
    spheres; frames (N, L, 4, 4) of the links ``names``."""
    F = 1 + max(row for row, *_ in spheres)
    out = np.full((len(frames), F), np.inf)
    for row, link, centres, radii in spheres:
        T = frames[:, names.index(link)]  # (N, 4, 4)
        world = np.einsum("nij,sj->nsi", T[:, :3, :3], centres) + T[:, None, :3, 3]
        gap = surface_distance_near(obj, world.reshape(-1, 3)).reshape(len(frames), -1) - radii
        out[:, row] = np.minimum(out[:, row], gap.min(axis=1))
    return out


def _pad_angles(robot: Robot, obj: Shape, head: torch.Tensor, q: torch.Tensor, names: list[str],
                frames: np.ndarray, fingers: Sequence[str], rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(N, k) each chosen pad normal's angle (degrees) to the inward normal at its touch point (inf
    where that point is off the surface, as :func:`_touch` judges), and those normals (N, k, 3):
    head (N, 6), q (N, F, j), the link frames (N, L, 4, 4) of ``names``."""
    R = frames[:, [names.index(robot.cfg.fingers[f].tip) for f in fingers], :3, :3]  # (N, k, 3, 3)
    t = robot.fingertips_world(head, q).numpy()[:, rows].reshape(-1, 3)
    _, outward, off_by = touch_points(obj, t)
    inward = -outward.reshape(len(q), len(rows), 3)
    pad = np.einsum("nkij,kj->nki", R, np.stack([robot.pads[f].normal for f in fingers]))
    angles = np.degrees(np.arccos(np.clip(np.sum(pad * inward, axis=-1), -1.0, 1.0)))
    off = off_by.reshape(angles.shape) > TOUCH_M  # e.g. a box's edge
    return np.where(off, np.inf, angles), inward


def check_pad_fingers(robot: Robot, fingers: Sequence[str]) -> None:
    """What choosing contacts needs of the robot (:func:`pad_contact_sets`): a free hand (its palm is
    placed: no arm, no shared joints) and a pad on each of ``fingers`` (checked by
    :func:`~graspnet_torch.tasks.auto_contacts.contact_fingers`); :class:`ProblemError` otherwise."""
    if robot.has_body or robot.shared.n:
        raise ProblemError(f"robot {robot.cfg.name}: contacts are chosen for a free hand (no arm, no shared joints); "
                           f"the shipped one is robot=hand")
    for f in fingers:
        if f not in robot.pads:
            raise ProblemError(f"fingers: {f} of robot {robot.cfg.name} has no pad (its config's fingers.{f}.pad), "
                               f"which choosing contacts needs")


def pad_contact_sets(robot: Robot, obj: Shape, n: int, fingers: Sequence[str] = ("thumb", "index", "middle"),
                     seed: int = 0, cone_deg: float = 30.0, penetration_m: float = 1e-3,
                     max_tries: int | None = None, stats: dict | None = None,
                     require: str | None = None) -> list[ContactSet]:
    """Up to ``n`` contact sets the hand touches with the pads of ``fingers`` (module docstring).

    Draws palm poses in batches of ``BATCH`` (``LINES`` closing lines per finger each, a random
    one of those that touch within the cone kept) until ``n`` are kept or ``max_tries`` palm
    poses (default ``50 n``) were drawn. Each set unpacks as ``(contacts (k, 3), normals (k, 3), posture)``
    (world; normals inward). ``stats``, if given, receives ``tried``, ``touching`` (every
    chosen pad reached the surface), ``facing`` (and within the cone), ``clean`` (and FCL-clean)
    and ``kept``. ``require``: keep only "opposed" sets (:func:`opposes` below ``OPPOSE``) or
    "force_closure" ones (None: every set); measured on the shipped hand (thumb, index, middle,
    its thumb pad facing the fingers), 64 sets, seed 0: a 6 cm cube 64 sets of 3136 palm poses (55
    force closure), a 4 cm sphere 64 of 1280 (62), glass3 64 of 1728 (53); 2.3-11 s on one thread.
    """
    check_pad_fingers(robot, contact_fingers(robot.finger_names, list(fingers), robot.cfg.name, "fingers"))
    rng = np.random.default_rng(seed)
    finger_names = list(robot.fingers)
    rows = [finger_names.index(f) for f in fingers]
    chosen = np.zeros(len(finger_names), dtype=bool)
    chosen[rows] = True
    if require not in (None, "opposed", "force_closure"):
        raise ProblemError(f"pad_contact_sets: require {require!r}: None, 'opposed' or 'force_closure'")
    depth = np.array([robot.pads[f].depth if f in robot.pads else 0.0 for f in finger_names])
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    front, face = _palm_front(robot)
    plane = np.linalg.svd(np.eye(3) - np.outer(front, front))[0][:, :2]  # (3, 2) the palm's plane
    reach = np.concatenate([robot.fingertips_palm(torch.as_tensor(q)).numpy()[rows] for q in (lo, hi)]) @ plane
    verts = np.asarray(obj.trimesh().vertices, dtype=np.float64)
    centre = np.asarray(obj.pose[:3], dtype=np.float64)
    spheres = _finger_spheres(robot)
    problem = placeholder_problem(robot, obj, fingers)
    scene = scene_for(robot, problem, penetration_m, False, fingers_apart=True)
    max_tries = 50 * n if max_tries is None else max_tries
    out: list[ContactSet] = []
    tried = touching = facing = clean = 0
    while len(out) < n and tried < max_tries:
        B = min(BATCH, max_tries - tried)
        tried += B
        R = Rotation.random(B, random_state=rng).as_matrix()  # (B, 3, 3) palm orientations
        lateral = reach.min(axis=0) + rng.random((B, 2)) * np.ptp(reach, axis=0)
        gap = GAP_M[0] + rng.random(B) * (GAP_M[1] - GAP_M[0])
        d = -np.einsum("bij,j->bi", R, front)  # world: from the object toward the palm
        c_palm = lateral @ plane.T + (face + _support(verts, centre, d) + gap)[:, None] * front  # object centre, palm
        span = hi - lo
        T = np.tile(np.eye(4), (B, 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = centre - np.einsum("bij,bj->bi", R, c_palm)
        head = torch.as_tensor(np.stack([matrix_to_pose_np(t) for t in T]))
        heads = head.repeat_interleave(LINES, dim=0)  # (B M, 6): LINES closing lines per palm
        q_open, q_close = closing_lines(robot, lo, span, rng, B * LINES)
        q_touch, touched, before = close_lines(robot, obj, heads, q_open, q_close, depth)
        q_rest = (q_open + torch.as_tensor(before)[..., None] * (q_close - q_open)).view(B, LINES, *lo.shape)[:, 0]
        names, frames = robot.link_frames_of(None, q_touch, heads)
        angles, inward = _pad_angles(robot, obj, heads, q_touch, names, frames, fingers, rows)
        angles, inward = angles.reshape(B, LINES, len(rows)), inward.reshape(B, LINES, len(rows), 3)
        clear = _clearance(obj, names, frames, spheres).reshape(B, LINES, -1) >= -penetration_m  # (B, M, F)
        good = touched[:, rows].reshape(B, LINES, len(rows)) & (angles <= cone_deg) & clear[:, :, rows]
        q_rest = q_open + torch.as_tensor(before)[..., None] * (q_close - q_open)
        rest_clear = _clearance(obj, *robot.link_frames_of(None, q_rest, heads), spheres).reshape(B, LINES, -1)
        pick = np.argmax(good + rng.random(good.shape), axis=1)  # (B, k): a random good line per finger
        if len(rows) > 1:  # the first finger (the thumb): its good line most opposed to the others' normals
            others = inward[np.arange(B)[:, None], pick[:, 1:], np.arange(1, len(rows))].mean(axis=1)  # (B, 3)
            oppose = -np.einsum("bmi,bi->bm", inward[:, :, 0], others)
            pick[:, 0] = np.argmax(np.where(good[:, :, 0], oppose, -np.inf), axis=1)
        rest = np.argmax((rest_clear >= -penetration_m) + rng.random(rest_clear.shape), axis=1)  # (B, F)
        q_touch, q_rest = q_touch.view(B, LINES, *lo.shape), q_rest.view(B, LINES, *lo.shape)
        q = torch.stack([q_rest[torch.arange(B), torch.as_tensor(rest[:, i]), i] for i in range(len(lo))], dim=1)
        for i, row in enumerate(rows):
            q[:, row] = q_touch[torch.arange(B), torch.as_tensor(pick[:, i]), row]
        ok = good.any(axis=1).all(axis=1)
        touching += int(ok.sum())
        for b in np.flatnonzero(ok):
            posture = Posture(palm_pose=head[b], fingers=q[b], body=torch.zeros(0, dtype=torch.float64))
            found = _touch(robot, obj, posture, fingers, cone_deg)
            if found is None:
                continue
            facing += 1
            if scene.check(posture).count:
                continue
            clean += 1
            contacts, normals, angles = found
            if not _required(require, contacts, normals, centre):
                continue
            out.append(ContactSet(tuple(fingers), contacts, normals, posture, angles))
            if len(out) == n:
                break
    if stats is not None:
        stats.update(tried=tried, touching=touching, facing=facing, clean=clean, kept=len(out))
    return out


def _touch(robot: Robot, obj: Shape, posture: Posture, fingers: Sequence[str], cone_deg: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The touch points (k, 3), inward normals (k, 3) and pad angles (k,) of a posture, or None
    where a pad is off the surface or turned beyond the cone."""
    R, t = tip_frames(robot, posture, fingers)
    depth = np.array([robot.pads[f].depth for f in fingers])
    outward = surface_normals(obj, t)
    contacts = t - (surface_distance(obj, t))[:, None] * outward
    if np.any(np.abs(surface_distance(obj, contacts)) > TOUCH_M) or \
            np.any(np.abs(np.linalg.norm(contacts - t, axis=1) - depth) > TOUCH_M):
        return None
    inward = -surface_normals(obj, contacts)
    pad = np.einsum("kij,kj->ki", R, np.stack([robot.pads[f].normal for f in fingers]))
    angles = np.degrees(np.arccos(np.clip(np.sum(pad * inward, axis=1), -1.0, 1.0)))
    if np.any(angles > cone_deg + 1e-9) or not math.isfinite(float(angles.sum())):
        return None
    return contacts, inward, angles


def opposes(normals: np.ndarray) -> float:
    """The first (thumb's) inward normal dotted with the others' mean (k, 3) -> (below ``OPPOSE``:
    opposed); 0 for one contact."""
    return 0.0 if len(normals) < 2 else float(normals[0] @ normals[1:].mean(axis=0))


def _required(require: str | None, contacts: np.ndarray, normals: np.ndarray, centre: np.ndarray) -> bool:
    """Whether a set meets ``require``: None, "opposed" (:func:`opposes`) or "force_closure"
    (:func:`~graspnet_torch.quality.grasp_quality`, friction ``FRICTION``, the centre as the centre of mass)."""
    if require is None:
        return True
    if require == "opposed":
        return opposes(normals) < OPPOSE
    return bool(np.asarray(grasp_quality(contacts[None], normals[None], centre[None], FRICTION).force_closure)[0])
