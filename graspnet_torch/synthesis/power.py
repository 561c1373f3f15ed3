"""Power grasps: the palm against the object and the fingers wrapped around it, touching with any
of their links (Feix et al.'s power grasps; GraspIt!'s approach-and-close), for where the pads
alone do not hold: objects larger or longer than the fingertips span.

A batch of ``BATCH`` palm poses at a time:

1. *Palm*: ``ACROSS_SHARE`` of the palm orientations put the object's long axis (its vertices'
   principal axis) across the palm (normal to its front and to the fingers' direction), turned
   about that axis at random and by ``JITTER_DEG`` about a random one; the rest are uniform. The
   object's centre lies at a random point of the palm's plane from just short of the knuckles to
   under the proximal phalanges (:func:`_band`; :func:`~graspnet_torch.synthesis.drafts.palm_poses`:
   the palm's front from the hand's kinematics, any palm geometry), and the hand is moved along
   its front until, its fingers open (:mod:`~graspnet_torch.synthesis.opening`: a random fraction
   of each joint's range from the limit away from closing, or from straight, 0, for a joint that
   bends either way), the palm lies ``GAP_M`` from the object (``ON_PALM`` of them; the rest a
   random gap up to the open fingertips' reach) or the fingers as near as they allow
   (:func:`_seated`); where a finger (a thumb over the palm) keeps the palm more than
   ``SEAT_TOL_M`` from that gap, up to ``REDRAWS`` other open postures are tried and the one
   that lets the palm nearest is kept.
2. *Fingers*: every finger closes (each joint that, at mid-range, moves its pad forward, along the
   pad's normal, by a cosine of ``FORWARD`` or more, toward the limit that does, from near the
   other; the others held) until one of its links meets the object
   (:func:`~graspnet_torch.synthesis.autograsp.close_fingers`, its boxes and meshes as
   ``LINK_POINTS`` points of their surfaces), then, ``WRAP_PHASES`` times, the joints beyond each
   touching link close on while those up to it hold (GraspIt!'s autograsp: the finger wraps;
   :func:`_wrap`). Fingers passing through each other are left to the check.
3. *Check*: kept where at least ``MIN_TOUCHING`` fingers touch, the FCL scene (every link, the
   fingers apart) finds no link deeper than ``PENETRATION_M`` in the object and no two fingers
   through each other, and the contacts (each touching link's nearest point of the object, the
   palm's among them: :func:`~graspnet_torch.synthesis.autograsp.link_contacts`; the object's
   inward normals there) are in force closure (friction ``FRICTION``).

Kept grasps are ranked by Ferrari-Canny epsilon and checked in physics in that order, the grasp's
squeeze closing every closing joint ``SQUEEZE_DEG`` further. A grasp's ``links`` are those
touching links; its ``type`` is "power" where the palm or a link other than a pad's touches, else
"precision"; its ``candidate`` lists every contact (``fingers``: the finger of each, the palm
link's name for the palm's), its ``problem`` one contact per touching finger (the first).
Everything is drawn from one ``numpy`` generator seeded by ``seed``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.collision.surface import surface_distance_near, surface_normals
from graspnet_torch.quality import GraspQuality, grasp_quality
from graspnet_torch.robot.geometry import palm_shapes, surface_points
from graspnet_torch.robot.opposition import hand_axes
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose, place_points_np
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.autograsp import (
    TOUCH_M,
    close_fingers,
    closed_result,
    finger_gaps,
    finger_spheres,
    link_contacts,
    placed_spheres,
)
from graspnet_torch.synthesis.candidates import FRICTION, ContactSet, placeholder_problem
from graspnet_torch.synthesis.closing import pad_forward
from graspnet_torch.synthesis.drafts import palm_front, palm_plane, palm_poses
from graspnet_torch.synthesis.grasp import SynthesizedGrasp
from graspnet_torch.synthesis.opening import draw_open
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["BATCH", "GAP_M", "MIN_TOUCHING", "PENETRATION_M", "SQUEEZE_DEG", "power_grasps"]

BATCH = 64  # palm poses drawn at once
GAP_M = (0.0, 0.001)  # the object's gap to the palm's face: it rests on the palm
MIN_TOUCHING = 2  # fingers that must touch
PENETRATION_M = 1e-3  # no link deeper than this in the object
SQUEEZE_DEG = 5.0  # the squeeze: each closing joint this much further
BAND = 1.5  # the object's centre lies from this many of its half widths short of the knuckles
CLAW = 0.3  # a hand whose fingers' mean direction leans from its front by less than this share is a claw
FAR = 0.5  # to this share of the fingers' length past them
FACE_M = 0.01  # the palm's face: its surface within this of its farthest point along the front
SEAT_STEPS = 3  # moves of the palm toward the object until it rests on it
ACROSS_SHARE = 0.75  # of each batch: palm poses with the object's long axis across the palm
JITTER_DEG = 15.0  # how far those turn from it (standard deviation)
ON_PALM = 0.5  # of each batch: the object resting on the palm; the rest a random gap up to the open fingertips'
# reach in front of it (fingers that stand out of the palm, as a Barrett hand's, close on it from there)
WRAP_PHASES = 3  # closings after the first: the joints beyond the touching links close on
LINK_POINTS = 64  # points spread over each finger link's box or mesh where the closing measures it
PALM_POINTS = 256  # points spread over each palm shape where its distance to the object is measured
REDRAWS = 3  # new open postures tried for a palm pose whose fingers keep the palm from its gap
SEAT_TOL_M = 0.002  # by more than this


def _palm_points(robot: Robot) -> np.ndarray:
    """(P, 3) points over the palm's collision surface, palm frame."""
    shapes = palm_shapes(robot.urdf, robot.cfg.palm_link)
    if not shapes:
        return np.zeros((0, 3))
    return np.concatenate([surface_points(s, P, PALM_POINTS, PALM_POINTS) for s, P in shapes])


def power_grasps(robot: Robot, obj: Shape, n_grasps: int, seed: int = 0, max_tries: int = 8 * BATCH,
                 physics: Callable[..., Any] | None = None, checks: int = 32, obstacles: Sequence[Shape] = (),
                 stats: dict | None = None) -> list[SynthesizedGrasp]:
    """Up to ``n_grasps`` power grasps of ``obj`` by the free hand ``robot`` (module docstring),
    from at most ``max_tries`` palm poses: with ``physics`` (a check ``physics(problem, result,
    robot=robot)``, i.e. ``gt.simulate_grasp``), the grasps of each batch checked in rank order
    (at most ``checks`` in all) until ``n_grasps`` hold every push, every checked one returned in
    the order checked; without, the best ``n_grasps`` by epsilon. A hand whose palm has no
    collision geometry has none (``[]``, ``stats`` untouched). ``stats`` receives
    ``power_tried``, ``power_touching`` (enough fingers touch), ``power_kept`` (FCL-clean, in force
    closure), ``power_checked`` and ``power_held``."""
    if not len(_palm_points(robot)):  # a holder with no palm to rest the object on (TriFinger's)
        return []
    rng = np.random.default_rng([seed, 1])
    counts = stats if stats is not None else {}
    counts.update(power_tried=0, power_touching=0, power_clean=0, power_kept=0, power_checked=0, power_held=0)
    scene = scene_for(robot, placeholder_problem(robot, obj, list(robot.fingers)[:2], None, obstacles), PENETRATION_M,
                      False, fingers_apart=True)
    out: list[SynthesizedGrasp] = []
    while counts["power_tried"] < max_tries and counts["power_checked"] < checks:
        B = min(BATCH, max_tries - counts["power_tried"])
        counts["power_tried"] += B
        for g in _batch(robot, obj, B, rng, scene, seed, obstacles, counts):
            if physics is not None:
                if counts["power_checked"] >= checks:
                    break
                counts["power_checked"] += 1
                g.physics = physics(g.problem, g.result, robot=robot)
                if g.holds == g.physics.of:
                    counts["power_held"] += 1
            out.append(g)
            if physics is not None and counts["power_held"] >= n_grasps:
                return out
        if physics is None and len(out) >= n_grasps:
            break
    return sorted(out, key=lambda g: -g.quality.epsilon)[:n_grasps] if physics is None else out


def _batch(robot: Robot, obj: Shape, B: int, rng: np.random.Generator, scene: Any, seed: int,
           obstacles: Sequence[Shape], counts: dict) -> list[SynthesizedGrasp]:
    """One batch of ``B`` palm poses closed onto the object (module docstring, steps 1-3): its kept
    grasps, best epsilon first."""
    names = list(robot.fingers)
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    palm_pts = _palm_points(robot)
    verts = np.asarray(obj.trimesh().vertices, dtype=np.float64)
    front, face, _, _ = palm_front(robot, list(range(len(names))))
    opposing = hand_axes(robot).opposing
    tips = robot.fingertips_palm(robot.home_posture().fingers).numpy()[[f != opposing for f in names]].mean(axis=0)
    plane, box = _band(robot, palm_pts[palm_pts @ front >= face - FACE_M], front, tips, verts)
    palm = (front, face, box, plane)
    spheres = finger_spheres(robot, surface=True, points=LINK_POINTS), finger_spheres(robot)
    centre = np.asarray(obj.pose[:3], dtype=np.float64)
    R = _across(rng, B, verts, front, tips)
    forward = pad_forward(robot, ((lo + hi) / 2)[None])[0]  # (F, n): at mid-range, how each joint moves its pad
    draw = partial(draw_open, forward, names.index(opposing), lo, hi, rng=rng)
    direction, q_open = draw(B)
    reach = robot.fingertips_palm(torch.as_tensor(q_open)).numpy() @ front - face  # (B, F): the open tips' reach
    palm_gap = np.where(rng.random(B) < ON_PALM, sum(GAP_M) / 2, rng.random(B) * np.maximum(reach.max(axis=1), 0.0))
    T = palm_poses(R, rng, palm, verts, centre, [], GAP_M)
    T, direction, q_open = _seated_best(robot, obj, T, (direction, q_open), draw, palm_pts, front, spheres[0], palm_gap)
    head = matrix_to_pose(torch.as_tensor(T, dtype=torch.float64))
    q_close = np.where(direction > 0, hi, np.where(direction < 0, lo, q_open))
    q, gaps = _wrap(robot, obj, head, torch.as_tensor(q_open), torch.as_tensor(q_close), spheres)
    touch = (gaps <= TOUCH_M) & (gaps >= -PENETRATION_M)
    rows = np.flatnonzero(touch.sum(axis=1) >= MIN_TOUCHING)
    counts["power_touching"] += len(rows)
    postures = [Posture(palm_pose=head[b], fingers=q[b], body=torch.zeros(0, dtype=torch.float64)) for b in rows]
    pads = {p.link for p in robot.pads.values()}
    owner = _owners(robot)
    out = []
    for b, posture, rep in zip(rows, postures, scene.check_many(postures) if postures else [], strict=True):
        counts["power_clean"] += not rep.count
        rated = None if rep.count else _rated(obj, posture, robot, owner, centre)
        if rated is None:
            continue
        links, cset, quality = rated
        squeeze = np.clip(q[b].numpy() + math.radians(SQUEEZE_DEG) * direction[b], lo, hi)
        first = {f: i for i, f in reversed(list(enumerate(cset.fingers))) if f in robot.fingers}
        if len(first) < MIN_TOUCHING:  # the palm and one finger within reach of the surface: no problem to state
            continue
        problem = placeholder_problem(robot, obj, tuple(first), cset.contacts[list(first.values())], obstacles)
        kind = "power" if any(link not in pads for link in links) else "precision"
        result = closed_result(robot, posture, squeeze, seed)
        if _deepest(robot, problem, trial_posture(robot, result.best)) > PENETRATION_M:
            continue
        out.append(SynthesizedGrasp(problem, cset, quality, result, links=links, type=kind))
    counts["power_kept"] += len(out)
    return sorted(out, key=lambda g: -g.quality.epsilon)


def _band(robot: Robot, face: np.ndarray, front: np.ndarray, tips: np.ndarray, verts: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Where the object's centre is drawn over the palm: the plane (3, 2) of the fingers' direction
    (``tips``, the other fingers' mean home fingertip, without its ``front`` part) and across it,
    and the box (2, 2) in it (low and high corner): along the fingers from ``BAND`` of the object's
    half width (half its second principal extent, ``verts`` (V, 3)) short of the knuckles (the
    other fingers' first movable joints) to ``FAR`` of the fingers' length past them (under the
    proximal phalanges: fingers that fold on themselves wrap no nearer the palm), across the palm's
    face ``face`` (P, 3). A claw (the fingers' mean direction within ``CLAW`` of the front, as a
    D'Claw's): the object's centre on the fingers' axis, within ``CLAW`` of their knuckles' mean
    distance from it."""
    opposing = hand_axes(robot).opposing
    names, frames = robot.link_frames_of(None, robot.home_posture().fingers[None] * 0,
                                         torch.zeros(1, 6, dtype=torch.float64))
    knuckles = np.asarray([frames[0, names.index(next(j for j in robot.urdf.path_joints(f.chain.root, f.chain.tip)
                                                      if j.type != "fixed").child), :3, 3]
                           for name, f in robot.fingers.items() if name != opposing])
    along_dir = tips - (tips @ front) * front
    if np.linalg.norm(along_dir) < CLAW * np.linalg.norm(tips):  # fingers along the front, around it: a claw
        plane = palm_plane(front)
        middle = knuckles.mean(axis=0) @ plane
        spread = CLAW * float(np.linalg.norm(knuckles @ plane - middle, axis=1).mean())
        return plane, np.stack([middle - spread, middle + spread])
    along_dir /= np.linalg.norm(along_dir)
    plane = np.stack([along_dir, np.cross(front, along_dir)], axis=1)
    line = float(np.mean(knuckles @ along_dir))
    centred = verts - verts.mean(axis=0)
    half = float(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][1])) / 2
    across = face @ plane[:, 1]
    box = np.array([[line - BAND * half, across.min()], [line + FAR * max(tips @ along_dir - line, 0.0), across.max()]])
    return plane, box


def _depths(robot: Robot, model: tuple) -> np.ndarray:
    """(s,) for each sphere of a finger model (:func:`~graspnet_torch.synthesis.autograsp.finger_spheres`):
    how many of its finger's free joints move its link."""
    names, _ = robot.link_frames_of(None, robot.home_posture().fingers[None], torch.zeros(1, 6, dtype=torch.float64))
    depth = {}
    for finger in robot.fingers.values():
        free = set(finger.joint_names)
        moving = 0
        for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip):
            moving += joint.name in free
            depth[joint.child] = moving
    return np.array([depth[names[k]] for k in model[1]])


def _wrap(robot: Robot, obj: Shape, head: torch.Tensor, q_open: torch.Tensor, q_close: torch.Tensor,
          spheres: tuple) -> tuple[torch.Tensor, np.ndarray]:
    """The fingers closed onto the object (:func:`~graspnet_torch.synthesis.autograsp.close_fingers`),
    then, ``WRAP_PHASES`` times, the joints beyond each finger's touching links closed on while
    those up to them hold (GraspIt!'s autograsp: a finger wraps): head (B, 6), q_open / q_close
    (B, F, n) -> the joints (B, F, n) and each finger's clearance (B, F) from the object."""
    rows, depth = spheres[0][0], _depths(robot, spheres[0])
    pairs = np.zeros(0, dtype=int), np.zeros(0, dtype=int)  # fingers through each other: the FCL check's
    B, F, n = q_open.shape
    mask = np.ones((B, len(rows)), dtype=bool)
    held = np.zeros((B, F), dtype=int)  # each finger's joints [0, held) hold
    q, target = q_open, q_close
    for _ in range(WRAP_PHASES):
        q, _ = close_fingers(robot, obj, head, q, target, spheres, pairs, mask)
        per = _sphere_gaps(robot, obj, head, q, spheres[0])
        touching = mask & (per <= TOUCH_M)
        for f in range(F):
            on = touching[:, rows == f]
            held[:, f] = np.maximum(held[:, f], np.where(on.any(axis=1), (on * depth[rows == f]).max(axis=1), 0))
        mask &= depth[None, :] > held[:, rows]
        target = torch.where(torch.as_tensor(np.arange(n)[None, None, :] < held[:, :, None]), q, q_close)
    return q, finger_gaps(robot, obj, head, q, spheres)[0]


def _sphere_gaps(robot: Robot, obj: Shape, head: torch.Tensor, q: torch.Tensor, model: tuple) -> np.ndarray:
    """(B, s) each sphere's clearance (m) from the object."""
    _, frames = robot.link_frames_of(None, q, head)
    world = placed_spheres(frames, model)
    return surface_distance_near(obj, world.reshape(-1, 3)).reshape(len(q), -1) - model[3]


def _across(rng: np.random.Generator, B: int, verts: np.ndarray, front: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """(B, 3, 3) palm orientations: ``ACROSS_SHARE`` of them with the object's long axis (its
    vertices' principal axis) across the palm (normal to the palm's front and to the fingers' mean
    direction ``tips``, palm frame), turned about that axis at random and by ``JITTER_DEG``
    (standard deviation) about a random one; the rest uniform."""
    R = Rotation.random(B, random_state=rng).as_matrix()
    n = int(B * ACROSS_SHARE)
    if n == 0:
        return R
    fingers = tips - (tips @ front) * front
    fingers /= np.linalg.norm(fingers)
    palm_axes = np.stack([front, fingers, np.cross(front, fingers)], axis=1)  # palm frame: front, fingers, across
    axis = np.linalg.svd(verts - verts.mean(axis=0), full_matrices=False)[2][0]
    axis = axis * rng.choice([-1.0, 1.0], n)[:, None]
    u = np.linalg.svd(np.eye(3) - np.outer(axis[0], axis[0]))[0][:, :2]  # normal to the axis
    a = rng.uniform(0.0, 2 * np.pi, n)
    f = np.cos(a)[:, None] * u[:, 0] + np.sin(a)[:, None] * u[:, 1]  # world: the palm's front
    world = np.stack([f, np.cross(axis, f), axis], axis=2)  # (n, 3, 3) columns: front, fingers, across
    jitter = Rotation.from_rotvec(rng.normal(size=(n, 3)) * math.radians(JITTER_DEG) / math.sqrt(3)).as_matrix()
    R[:n] = jitter @ world @ palm_axes.T
    return R


def _palm_gap(obj: Shape, T: np.ndarray, palm_pts: np.ndarray) -> np.ndarray:
    """(B,) the palm's gap to the object (m) at palm poses ``T`` (B, 4, 4); ``palm_pts`` (P, 3), palm frame."""
    world = place_points_np(T, palm_pts)
    return surface_distance_near(obj, world.reshape(-1, 3)).reshape(len(T), -1).min(axis=1)


def _seated_best(robot: Robot, obj: Shape, T: np.ndarray, drawn: tuple[np.ndarray, np.ndarray], draw: Callable,
                 palm_pts: np.ndarray, front: np.ndarray, model: tuple, palm_gap: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The palm poses ``T`` (B, 4, 4) seated (:func:`_seated`) with their open postures ``drawn``
    (closing directions, open postures: (B, F, n) each); where a finger stops the palm more than
    ``SEAT_TOL_M`` short of its ``palm_gap`` (B,) (a thumb lying over the palm), up to ``REDRAWS``
    new open postures (``draw(n)``) are seated too and the one whose palm comes nearest its gap is
    kept. Returned: the poses, closing directions and open postures."""
    direction, q_open = (a.copy() for a in drawn)
    seated = _seated(robot, obj, T, torch.as_tensor(q_open), palm_pts, front, model, palm_gap)
    miss = _palm_gap(obj, seated, palm_pts) - palm_gap
    for _ in range(REDRAWS):
        rows = np.flatnonzero(miss > SEAT_TOL_M)
        if not len(rows):
            break
        d, q = draw(len(rows))
        again = _seated(robot, obj, T[rows], torch.as_tensor(q), palm_pts, front, model, palm_gap[rows])
        gap = _palm_gap(obj, again, palm_pts) - palm_gap[rows]
        better = gap < miss[rows]
        keep = rows[better]
        seated[keep], direction[keep], q_open[keep], miss[keep] = again[better], d[better], q[better], gap[better]
    return seated, direction, q_open


def _seated(robot: Robot, obj: Shape, T: np.ndarray, q_open: torch.Tensor, palm_pts: np.ndarray, front: np.ndarray,
            model: tuple, palm_gap: np.ndarray) -> np.ndarray:
    """Palm poses (B, 4, 4) moved along their front axis (palm frame ``front``) until the palm's
    nearest point ``palm_pts`` (P, 3) lies ``palm_gap`` (B,) from the object, or, where the hand's
    fingers at their open postures q_open (B, F, n) (as ``model``,
    :func:`~graspnet_torch.synthesis.autograsp.finger_spheres`) would then come nearer than
    ``GAP_M``'s middle, as near as they allow (``SEAT_STEPS`` moves by the gap found: exact for
    a face parallel to the object's nearest face)."""
    T = T.copy()
    d = np.einsum("bij,j->bi", T[:, :3, :3], front)  # world: the palm's front
    for _ in range(SEAT_STEPS):
        palm = _palm_gap(obj, T, palm_pts)
        head = matrix_to_pose(torch.as_tensor(T, dtype=torch.float64))
        fingers = _sphere_gaps(robot, obj, head, q_open, model).min(axis=1)
        T[:, :3, 3] += np.minimum(palm - palm_gap, fingers - sum(GAP_M) / 2)[:, None] * d
    return T


def _deepest(robot: Robot, problem: GraspProblem, posture: Posture) -> float:
    """The deepest any link of ``posture`` lies in the problem's object (m; FCL, every link, each
    depth measured in full: the scene that counts links beyond a tolerance may stop short of it)."""
    report = scene_for(robot, problem, 0.0, False).check(posture)
    return max(report.object_links.values(), default=0.0)


def _owners(robot: Robot) -> dict[str, str]:
    """Link -> the finger it moves with (a finger's links from its root to its tip)."""
    return {joint.child: name for name, finger in robot.fingers.items()
            for joint in robot.urdf.path_joints(finger.chain.root, finger.chain.tip)}


def _rated(obj: Shape, posture: Posture, robot: Robot, owner: dict[str, str], centre: np.ndarray
           ) -> tuple[tuple[str, ...], ContactSet, GraspQuality] | None:
    """A clean closed posture's touching links and contacts (:func:`~graspnet_torch.synthesis.autograsp.link_contacts`)
    with the object's inward normals there, their quality; None where they are not in force closure."""
    links, contacts = link_contacts(robot, obj, posture, TOUCH_M)
    if len(links) < 2:
        return None
    normals = -surface_normals(obj, contacts)
    q = grasp_quality(contacts, normals, centre, FRICTION)
    if not q.force_closure:
        return None
    fingers = tuple(owner.get(link, link) for link in links)  # a link of no finger's: the palm's
    cset = ContactSet(fingers, contacts, normals, posture, np.full(len(contacts), np.nan))
    return links, cset, GraspQuality(float(q.epsilon), float(q.min_singular_value), True)
