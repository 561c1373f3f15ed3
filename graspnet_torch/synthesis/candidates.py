"""Contact sets a hand can touch with its pads: the drafts of
:mod:`~graspnet_torch.synthesis.drafts` (sampled hand postures whose chosen fingers' pads rest on
the object's surface, facing into it), each checked as the solver will see it (:class:`SetCheck`):
the inward normals at its contacts as the surface contact model takes them
(:func:`~graspnet_torch.collision.surface.surface_normals`: on a mesh's edge, the face it takes),
every tip within ``TOUCH_M`` of its target (the pad's depth out from the contact along that
normal) and every pad within the cone; and the FCL scene of the surface model finding no link
deeper than ``penetration_m`` in the object and no two fingers through each other.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace

import numpy as np

from graspnet_torch.collision.cache import scene_for
from graspnet_torch.collision.surface import surface_normals
from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import grasp_quality
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver.contact import tip_frames
from graspnet_torch.synthesis.drafts import (
    COMBOS,
    GAP_SHARE,
    TOUCH_M,
    ContactSet,
    check_pad_fingers,
    iter_contact_drafts,
)
from graspnet_torch.tasks.auto_contacts import contact_fingers
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["COMBOS", "FRICTION", "GAP_SHARE", "OPPOSE", "TOUCH_M", "ContactSet", "SetCheck", "check_pad_fingers",
           "iter_contact_sets", "opposes", "pad_contact_sets", "placeholder_problem"]

OPPOSE = -0.3  # "opposed": the thumb's inward normal dotted with the others' mean lies below this
FRICTION = 0.6  # the friction grasp quality and "force_closure" are measured with (the physics check's too)


def placeholder_problem(robot: Robot, obj: Shape, fingers: Sequence[str], contacts: np.ndarray | None = None,
                        obstacles: Sequence[Shape] = ()) -> GraspProblem:
    """A problem of ``robot`` holding ``obj`` among ``obstacles`` (contacts (k, 3), world; None: its centre)."""
    T = np.eye(4)
    T[:3, :3] = pose_to_matrix_np(obj.pose)[:3, :3]
    T[:3, 3] = obj.pose[:3]
    pts = np.tile(obj.pose[:3], (len(fingers), 1)) if contacts is None else np.asarray(contacts).reshape(-1, 3)
    local = (pts - T[:3, 3]) @ T[:3, :3]
    data = {"robot": robot.cfg.name, "object": obj.to_mapping(),
            "contacts": [{"finger": f, "position": p.tolist()} for f, p in zip(fingers, local, strict=True)],
            "obstacles": [o.to_mapping() for o in obstacles]}
    return GraspProblem.from_mapping(data, robot_cfg=robot.cfg, allow_outside_paths=True)


class SetCheck:
    """The check that makes a draft a contact set (module docstring), for one robot, object and
    fingers: ``check(draft)`` is the contact set (its normals and pad angles as the solver sees
    them) or None. ``stats``, if given, counts the drafts checked that were ``facing`` (within the
    cone, on target) and ``clean`` (and FCL-clean)."""

    def __init__(self, robot: Robot, obj: Shape, fingers: Sequence[str], cone_deg: float = 30.0,
                 penetration_m: float = 1e-3, obstacles: Sequence[Shape] = (), stats: dict | None = None) -> None:
        check_pad_fingers(robot, contact_fingers(robot.finger_names, list(fingers), robot.cfg.name, "fingers"))
        self.robot, self.obj, self.fingers, self.cone_deg = robot, obj, tuple(fingers), cone_deg
        self.scene = scene_for(robot, placeholder_problem(robot, obj, fingers, None, obstacles), penetration_m, False,
                               fingers_apart=True)
        self.counts = stats if stats is not None else {}
        self.counts.update(facing=0, clean=0)

    def __call__(self, draft: ContactSet) -> ContactSet | None:
        found = _as_solved(self.robot, self.obj, draft.posture, self.fingers, draft.contacts, self.cone_deg)
        if found is None:
            return None
        self.counts["facing"] += 1
        if self.scene.check(draft.posture).count:
            return None
        self.counts["clean"] += 1
        return replace(draft, normals=found[0], angles_deg=found[1])


def pad_contact_sets(robot: Robot, obj: Shape, n: int, fingers: Sequence[str] = ("thumb", "index", "middle"),
                     seed: int = 0, cone_deg: float = 30.0, penetration_m: float = 1e-3,
                     max_tries: int | None = None, stats: dict | None = None, require: str | None = None,
                     orientations: Callable[[np.random.Generator, int], np.ndarray] | None = None,
                     reachable: Callable[[np.ndarray], np.ndarray] | None = None, obstacles: Sequence[Shape] = ()
                     ) -> list[ContactSet]:
    """Up to ``n`` contact sets the hand touches with the pads of ``fingers`` (module docstring):
    the first ``n`` of :func:`iter_contact_sets` (same arguments), drawing at most ``max_tries``
    palm poses (default ``50 n``). Each set unpacks as ``(contacts (k, 3), normals (k, 3), posture)``
    (world; normals inward). ``stats``, if given, receives ``tried``, ``touching`` (every chosen
    pad reached the surface), ``drafts``, ``facing`` (and within the cone), ``clean`` (and FCL-clean) and
    ``kept``."""
    out: list[ContactSet] = []
    for batch in iter_contact_sets(robot, obj, fingers, seed, cone_deg, penetration_m,
                                   50 * n if max_tries is None else max_tries, stats, require, orientations,
                                   reachable, obstacles):
        out.extend(batch[: n - len(out)])
        if len(out) == n:
            break
    if stats is not None:
        stats["kept"] = len(out)
    return out


def iter_contact_sets(robot: Robot, obj: Shape, fingers: Sequence[str] = ("thumb", "index", "middle"),
                      seed: int = 0, cone_deg: float = 30.0, penetration_m: float = 1e-3, max_tries: int = 3200,
                      stats: dict | None = None, require: str | None = None,
                      orientations: Callable[[np.random.Generator, int], np.ndarray] | None = None,
                      reachable: Callable[[np.ndarray], np.ndarray] | None = None, obstacles: Sequence[Shape] = ()
                      ) -> Iterator[list[ContactSet]]:
    """The contact sets of each batch of palm poses, batch after batch, until ``max_tries`` palm
    poses were drawn: the drafts of :func:`~graspnet_torch.synthesis.drafts.iter_contact_drafts`
    (same arguments) that pass :class:`SetCheck` (``obstacles``: a set whose links meet one, a
    table, is dropped). ``stats`` as :func:`pad_contact_sets` (updated after every batch);
    ``require``: keep only "opposed" sets (:func:`opposes` below ``OPPOSE``) or "force_closure" ones
    (None: every set)."""
    if require not in (None, "opposed", "force_closure"):
        raise ProblemError(f"pad_contact_sets: require {require!r}: None, 'opposed' or 'force_closure'")
    centre = np.asarray(obj.pose[:3], dtype=np.float64)
    counts = stats if stats is not None else {}
    drafts = iter_contact_drafts(robot, obj, fingers, seed, cone_deg, penetration_m, max_tries, counts, orientations,
                                 reachable)
    check = SetCheck(robot, obj, fingers, cone_deg, penetration_m, obstacles, counts)
    for batch in drafts:
        sets = (check(d) for d in batch)
        yield [s for s in sets if s is not None and _required(require, s.contacts, s.normals, centre)]


def _as_solved(robot: Robot, obj: Shape, posture: Posture, fingers: Sequence[str], contacts: np.ndarray,
               cone_deg: float) -> tuple[np.ndarray, np.ndarray] | None:
    """A set as the surface model's solver sees it: the inward normals (k, 3) at its contacts by
    :func:`~graspnet_torch.collision.surface.surface_normals` (on a mesh's edge, the face it takes)
    and the pad angles (k,) to them; None where a tip lies farther than ``TOUCH_M`` from the tip
    target those normals give (the pad's depth out from the contact) or a pad beyond the cone."""
    R, t = tip_frames(robot, posture, fingers)
    inward = -surface_normals(obj, contacts)
    depth = np.array([robot.pads[f].depth for f in fingers])
    pad = np.einsum("kij,kj->ki", R, np.stack([robot.pads[f].normal for f in fingers]))
    angles = np.degrees(np.arccos(np.clip(np.sum(pad * inward, axis=1), -1.0, 1.0)))
    if np.linalg.norm(t - (contacts - depth[:, None] * inward), axis=1).max() > TOUCH_M or angles.max() > cone_deg:
        return None
    return inward, angles


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
