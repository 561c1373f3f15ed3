"""How a contact finger touches its contact: the problem's contact model, where the tip frames go,
and what the surface model reports of a trial.

``solver.contact_model``:

- ``point`` (the paper's): the finger's tip frame on the contact. The contact fingers' distal
  links may touch the object at any depth; other links count beyond 2 mm.
- ``surface``: the finger's pad (:mod:`graspnet_torch.robot.pads`: a point and an outward normal in
  its tip frame) on the contact, facing into the object. The tip frame goes where the pad touches
  the contact with its normal along the object's inward normal (``c + depth n``,
  :func:`~graspnet_torch.collision.surface.pad_targets`); no link of the robot, the contact
  fingers' distal links included, may lie deeper than ``solver.penetration_mm`` in the object; a
  trial is a grasp only where every pad normal lies within ``solver.normal_cone_deg`` of the
  object's inward normal at its contact.
- ``auto`` (the default): ``surface`` where the problem has an object and the robot has pads
  (fingers), else ``point`` (no surface to touch: random reachable problems, sequences; a gripper's
  two points).

A rounded pad (the shipped hand's, every derived pad whose normal line meets the distal surface)
touches where its sphere (centre: the tip frame, radius: the pad's depth) meets the object: the
reported ``pad_distance_mm`` is the distance from the contact to that sphere, | |c - tip| - depth |,
and ``normal_angle_deg`` the angle between the pad normal (turned with the tip frame) and the
object's inward normal at the contact.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.collision.scene import OBJECT_TOLERANCE_M, CollisionScene, has_environment
from graspnet_torch.collision.surface import pad_targets, surface_distance, surface_normals
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.heads import head_of
from graspnet_torch.robot.ik import refine
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["OFF_SURFACE_MM", "POINT_RULE", "ContactRule", "contact_model", "contact_rule", "describe_pad",
           "grasp_postures", "off_surface", "posture_fields", "surface_fields", "tip_frames",
           "tip_targets", "within_cone"]


def contact_model(robot: Robot, problem: GraspProblem, solver: SolverCfg) -> str:
    """'surface' or 'point' for this robot and problem (module docstring). Refuses
    (:class:`ProblemError`) ``surface`` asked for where there is no surface or no pad."""
    if solver.contact_model == "point":
        return "point"
    can = problem.object is not None and bool(problem.fingers) and bool(robot.pads)
    if solver.contact_model == "surface" and not can:
        why = "no object" if problem.object is None else "no fingers with pads"
        raise ProblemError(f"{problem.source}: solver.contact_model=surface needs an object and contact fingers "
                           f"with pads ({why}); use contact_model=point or auto")
    return "surface" if can else "point"


OFF_SURFACE_MM = 2.0  # a contact farther than this from the object's surface is said (surface model)


def off_surface(robot: Robot, problem: GraspProblem, solver: SolverCfg) -> str | None:
    """In the surface model, the contacts farther than :data:`OFF_SURFACE_MM` from the object's
    surface, in one line (a point-model problem's contacts, the fingertip centres, lie a fingertip
    radius out: the pads would touch nothing); None where every contact is on it, or in the point model."""
    if contact_model(robot, problem, solver) != "surface":
        return None
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    far = [(f, d) for f, d in zip(problem.fingers, np.abs(surface_distance(problem.object, contacts)) * 1000,
                                  strict=True) if d > OFF_SURFACE_MM]
    if not far:
        return None
    return (f"{problem.source}: contact(s) off the object's surface ({', '.join(f'{f} {d:.1f} mm' for f, d in far)}): "
            f"the surface model puts each finger's pad on its contact (solver.contact_model=point puts the "
            f"fingertip's centre there)")


@dataclass(frozen=True)
class ContactRule:
    """What a contact model asks of a grasp: ``model`` ('surface' | 'point'), how deep a link may
    go into the object (``object_tolerance``, m), whether the contact fingers' distal links may
    touch it at any depth (``touching``), the pads' cone (``cone_deg``; the surface model), and
    the scene that counts collisions so (:meth:`scene`)."""

    model: str
    object_tolerance: float
    touching: bool
    cone_deg: float

    @property
    def surface(self) -> bool:
        return self.model == "surface"

    def scene(self, robot: Robot, problem: GraspProblem) -> CollisionScene:
        """The FCL scene that counts a grasp's collisions under this rule (cached): the surface
        model counts every link beyond ``object_tolerance`` and two fingers through each other."""
        return scene_for(robot, problem, self.object_tolerance, self.touching, fingers_apart=self.surface)

    @classmethod
    def of(cls, model: str, solver: SolverCfg) -> ContactRule:
        surface = model == "surface"
        return cls(model, solver.penetration_mm / 1000 if surface else OBJECT_TOLERANCE_M, not surface,
                   solver.normal_cone_deg)


POINT_RULE = ContactRule("point", OBJECT_TOLERANCE_M, True, 180.0)  # the paper's model, whatever the settings


def contact_rule(robot: Robot, problem: GraspProblem, solver: SolverCfg) -> ContactRule:
    """The collision rule of the problem's contact model (:func:`contact_model`)."""
    return ContactRule.of(contact_model(robot, problem, solver), solver)


def tip_targets(robot: Robot, problem: GraspProblem, model: str) -> np.ndarray:
    """(k, 3) where the contact fingers' tip frames go (world, the problem's ``fingers`` order):
    the contacts (point), or where each pad touches its contact (surface)."""
    if model == "surface":
        return pad_targets(robot, problem)
    return np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)


def tip_frames(robot: Robot, posture: Posture, fingers: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """The tip frames of ``fingers`` in a posture, from the link frames (the robot's kernel):
    R (k, 3, 3), t (k, 3) (a tip offset moves the origin, not the axes)."""
    R, t = robot.tip_frames_at(*robot.link_frames_array([posture]), fingers)
    return R[0], t[0]


def surface_fields(robot: Robot, problem: GraspProblem, postures: Sequence[Posture]) -> list[dict]:
    """The surface model's fields of trials at ``postures`` (docs/contact.md), one forward
    kinematics and one collision pass for them all: per contact finger the pad's distance to its
    contact (mm) and its normal's angle to the object's inward normal (degrees), and the deepest
    link in the object (mm, FCL: every link, the contact fingers' distal links included; 0 where
    none touches it); the cone is checked by :func:`within_cone`."""
    if not postures:
        return []
    fingers = problem.fingers
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    R, t = robot.tip_frames_at(*robot.link_frames_array(postures), fingers)  # (B, k, 3, 3), (B, k, 3)
    pads = robot.pads
    depth = np.array([pads[f].depth for f in fingers])
    normal = np.einsum("bkij,kj->bki", R, np.stack([pads[f].normal for f in fingers]))
    inward = -surface_normals(problem.object, contacts)
    angle = np.degrees(np.arccos(np.clip(np.sum(normal * inward, axis=-1), -1.0, 1.0)))  # (B, k)
    distance = np.abs(np.linalg.norm(contacts - t, axis=-1) - depth) * 1000
    deepest = [0.0] * len(postures)
    if has_environment(robot, problem):
        reports = scene_for(robot, problem, 0.0, False).check_many(postures)
        deepest = [max(r.object_links.values(), default=0.0) * 1000 for r in reports]
    return [{"contact_model": "surface",
             "pad_distance_mm": {f: float(d) for f, d in zip(fingers, distance[b], strict=True)},
             "normal_angle_deg": {f: float(a) for f, a in zip(fingers, angle[b], strict=True)},
             "penetration_mm": float(deepest[b])} for b in range(len(postures))]


PREGRASP_STEPS = 20  # least-squares steps that put the fingertips on the pre-grasp's and the squeeze's targets,
PREGRASP_TOL_M = 1e-7  # a fingertip stopping within this of its target (3-5 steps; one a joint limit keeps off
# its target, a few mm, runs them all: 60 steps, before, cost 20 trials 46 ms against 22 ms at 20 steps)


def grasp_postures(robot: Robot, problem: GraspProblem, postures: Sequence[Posture], solver: SolverCfg
                   ) -> list[tuple[Posture, Posture]] | None:
    """The pre-grasp and the squeeze of each surface grasp of ``postures``: the palm (and an arm)
    where the grasp has it, each contact finger's tip target moved along the object's outward
    normal at its contact, by ``solver.pregrasp_mm`` out (the pads backed off) and
    ``solver.squeeze_mm`` in (pressed further), its joints by least squares within their limits
    from the grasp's (every posture and both moves in one batch); the other fingers as in the
    grasp. None for a hand whose fingers share joints (their bases move with them)."""
    if robot.shared.n:
        return None
    if not postures:
        return []
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64).reshape(-1, 3)
    normals = surface_normals(problem.object, contacts)
    tips = tip_targets(robot, problem, "surface")
    rows = [robot.finger_index(f) for f in problem.fingers]
    head = torch.stack([head_of(robot).values(p) for p in postures])  # (T, n)
    q0 = torch.stack([p.fingers for p in postures])  # (T, F, j)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    shifts = (solver.pregrasp_mm / 1000, -solver.squeeze_mm / 1000)
    targets = head_of(robot).fingertips(head, q0).repeat(len(shifts), 1, 1, 1)  # (2, T, F, 3): every finger where it is
    for k, shift in enumerate(shifts):
        targets[k][:, rows] = torch.as_tensor(tips + shift * normals)
    bases = head_of(robot).world_to_bases(targets, head.expand(len(shifts), -1, -1))
    q, _ = refine(robot.fingertips_base_jacobian, q0.expand(len(shifts), -1, -1, -1), bases, lo, hi, PREGRASP_STEPS,
                  tol=PREGRASP_TOL_M)
    return [(replace(p, fingers=q[0, t]), replace(p, fingers=q[1, t])) for t, p in enumerate(postures)]


def posture_fields(robot: Robot, posture: Posture) -> dict:
    """A posture in the result's format: ``palm_pose`` (m, degrees), ``joints`` (file units) and,
    for a robot with a body, ``arm_joints``."""
    pose = posture.palm_pose.tolist()
    out = {"palm_pose": pose[:3] + [math.degrees(a) for a in pose[3:]],
           "joints": robot.finger_joints_to_file(posture.fingers, posture.shared)}
    if head_of(robot).anchored:
        out["arm_joints"] = robot.body_joints_to_file(posture.body)
    return out


def within_cone(fields: dict, cone_deg: float) -> bool:
    """Whether every pad normal of a trial's surface fields lies within ``cone_deg``."""
    return all(a <= cone_deg + 1e-9 for a in fields["normal_angle_deg"].values())


def describe_pad(fields: dict) -> str:
    """The worst pad of a trial in a few words (a failure's reason)."""
    worst = max(fields["normal_angle_deg"], key=fields["normal_angle_deg"].get)
    return f"{worst}'s pad turned {fields['normal_angle_deg'][worst]:.0f} degrees from the object's normal"

