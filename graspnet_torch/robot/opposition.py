"""Which way a hand grasps, from its kinematics: its palm's front, the finger that opposes the
others and the default fingers of a grasp, for any hand (no finger names assumed).

All are read in the palm frame, at the robot's home posture unless said, from the fingers' pads
(:mod:`graspnet_torch.robot.pads`: each pad's normal faces where that finger presses):

- the *opposing finger*: the finger whose pad normal points most against the mean of the other
  fingers' (the smallest ``n_i . mean_{j != i} n_j`` over the home posture and the postures with
  every joint at ``FRACTIONS`` of its range: a thumb held out sideways at home opposes as it
  closes); on a human-like hand the thumb, on a
  Barrett-like hand the finger facing the two that spread, on a hand of alike fingers around an
  axis (TriFinger, D'Claw) any of them (the first of the ties, in the config's order);
- the *extension*: the unit direction from the palm frame's origin to the mean home fingertip;
- the palm's *front*: the side of the palm the fingers close toward, where an object is held:
  the normal of the plane through the fingers' first movable joints (the knuckles; least squares),
  on the side of the fingertips with every joint at the middle of its range; where the knuckles
  lie on a line (two fingers, or alike fingers from one point), the other fingers' mean pad normal
  without its component along the extension. Where that direction lies within ``SNAP_DEG`` of an
  axis of the palm frame (URDF palm frames are drawn along the palm's faces), that axis;
- the *default fingers* of a grasp: the opposing finger first, then the fingers whose home
  fingertips lie nearest its own, up to ``DEFAULT_COUNT`` (every finger of a smaller hand).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.pads import Pad, derived_pad

__all__ = ["DEFAULT_COUNT", "SNAP_DEG", "HandAxes", "default_fingers", "facing_pads", "hand_axes"]

SNAP_DEG = 25.0  # a front within this of a palm-frame axis is that axis
DEFAULT_COUNT = 3  # the default fingers of a grasp: the opposing one and its nearest neighbours
OPPOSE_MAX = 0.0  # the opposing finger's pad faces the others' mean at an angle over 90 degrees
FLAT = 0.1  # knuckles whose second singular value is under this share of the first lie on a line
SIDEWAYS = 0.3  # a facing direction mostly along the distal phalanx (less than this across it) is not a pad's
TIE = 1e-6  # oppositions within this of the least are ties
FRACTIONS = (0.25, 0.5, 0.75)  # postures (every joint at this fraction of its range) where fingers may oppose


class _Robot(Protocol):  # what hand_axes reads of a Robot
    cfg: Any
    urdf: Any
    fingers: dict[str, Any]
    body_joint_names: tuple[str, ...]
    has_body: bool

    @property
    def pads(self) -> dict[str, Any]: ...

    @property
    def finger_limits(self) -> tuple[np.ndarray, np.ndarray]: ...

    def home_posture(self, dtype: torch.dtype = torch.float64) -> Any: ...

    def fingertips_palm(self, q: torch.Tensor) -> torch.Tensor: ...

    def link_frames_of(self, body: Any, fingers: torch.Tensor, palm_pose: torch.Tensor | None = None,
                       shared: Any = None) -> tuple[list[str], np.ndarray]: ...


@dataclass(frozen=True, eq=False)
class HandAxes:
    """How a hand grasps (module docstring), in its palm frame.

    Attributes:
        front: (3,) unit: the side of the palm the fingers close toward.
        extension: (3,) unit: from the palm frame's origin toward the mean home fingertip.
        opposing: the finger whose pad faces the others'.
        opposition: (F,) each finger's least ``n_i . mean_{j != i} n_j`` over the postures (-1: its
            pad faces the others' exactly).
        order: every finger, the opposing one first, the others by their home fingertips' distance
            (m) to its fingertip, nearest first.
        normals: (F, 3) the pads' unit normals at the home posture, in the robot's finger order.
        tips: (F, 3) the home fingertips (m), in the robot's finger order.
    """

    front: np.ndarray
    extension: np.ndarray
    opposing: str
    opposition: np.ndarray
    order: tuple[str, ...]
    normals: np.ndarray
    tips: np.ndarray


def _palm_frames(robot: _Robot, q: torch.Tensor) -> tuple[list[str], np.ndarray]:
    """The links' names and poses (L, 4, 4) in the palm frame at the finger joints ``q`` (F, n)
    (an arm's joints at 0)."""
    body = torch.zeros(1, len(robot.body_joint_names), dtype=torch.float64) if robot.has_body else None
    names, frames = robot.link_frames_of(body, q[None], torch.zeros(1, 6, dtype=torch.float64))
    return names, np.linalg.inv(frames[0, names.index(robot.cfg.palm_link)]) @ np.asarray(frames[0])


def _pad_normals(robot: _Robot, q: torch.Tensor, pads: dict[str, Pad]) -> np.ndarray:
    """(F, 3) every finger's pad normal (``pads``) in the palm frame at the finger joints ``q`` (F, n)."""
    names, frames = _palm_frames(robot, q)
    return np.stack([frames[names.index(robot.cfg.fingers[f].tip), :3, :3] @ pads[f].normal for f in robot.fingers])


def _postures(robot: _Robot) -> list[torch.Tensor]:
    """The finger joints (F, n) where fingers may oppose: home, then every joint at ``FRACTIONS``."""
    lo, hi = (torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in robot.finger_limits)
    return [robot.home_posture().fingers.to(torch.float64), *(lo + u * (hi - lo) for u in FRACTIONS)]


def _opposition(normals: np.ndarray) -> np.ndarray:
    """(F,) each pad normal (F, 3) dotted with the mean of the others'."""
    others = (normals.sum(axis=0)[None] - normals) / (len(normals) - 1)
    return np.einsum("fi,fi->f", normals, others)


def _knuckle_normal(robot: _Robot, mid: torch.Tensor) -> np.ndarray | None:
    """(3,) unit normal of the plane through the fingers' first movable joints (palm frame, every
    joint at 0), toward the mean fingertip at the finger joints ``mid`` (F, n); None where they lie
    on a line (their second singular value under ``FLAT`` of the first)."""
    names, frames = _palm_frames(robot, torch.zeros_like(mid))
    knuckles = []
    for finger in robot.fingers.values():
        joint = next(j for j in robot.urdf.path_joints(finger.chain.root, finger.chain.tip) if j.type != "fixed")
        knuckles.append(frames[names.index(joint.child), :3, 3])
    knuckles = np.asarray(knuckles)
    centre = knuckles.mean(axis=0)
    _, sv, vt = np.linalg.svd(knuckles - centre)
    if len(knuckles) < 3 or not sv[1] > FLAT * sv[0]:
        return None
    normal = vt[2]
    side = (robot.fingertips_palm(mid).numpy().mean(axis=0) - centre) @ normal
    return normal if side >= 0 else -normal


def _snap(v: np.ndarray) -> np.ndarray:
    """``v`` (3,) unit, or the palm-frame axis (signed) within ``SNAP_DEG`` of it."""
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) >= np.cos(np.radians(SNAP_DEG)):
        axis = np.zeros(3)
        axis[k] = np.sign(v[k])
        return axis
    return v


def _opposing(robot: _Robot, pads: dict[str, Pad]) -> tuple[int, np.ndarray, int]:
    """The opposing finger's row, every finger's least opposition (F,) and the posture
    (:func:`_postures`' index) where the opposing finger opposes most; :class:`ConfigError` where
    none opposes (module docstring)."""
    names = list(robot.fingers)
    table = np.stack([_opposition(_pad_normals(robot, q, pads)) for q in _postures(robot)])  # (P, F)
    opposition = table.min(axis=0)
    o = int(np.flatnonzero(opposition <= opposition.min() + TIE)[0])  # ties: the first in the config's order
    if not opposition[o] < OPPOSE_MAX:
        angles = ", ".join(f"{n} {np.degrees(np.arccos(np.clip(c, -1, 1))):.0f}" for n, c in zip(names, opposition,
                                                                                                   strict=True))
        raise ConfigError(f"{robot.cfg.source}: fingers: no finger's pad opposes the others' (the angle of each pad "
                          f"normal to the others' mean over the postures, degrees: {angles}; one over 90 is needed): "
                          f"give the pads that face each other (fingers.<name>.pad)")
    return o, opposition, int(np.argmin(table[:, o]))


def _check_hand(robot: _Robot, pads: dict[str, Pad]) -> None:
    if len(robot.fingers) < 2 or not pads:
        raise ConfigError(f"{robot.cfg.source}: fingers: a grasp needs at least 2 fingers with pads, the robot has "
                          f"{len(pads)}")


def facing_pads(robot: _Robot, pads: dict[str, Pad]) -> dict[str, Pad]:
    """``pads`` (:func:`~graspnet_torch.robot.pads.finger_pads`) with the opposing finger's derived
    pad turned to face the others': its normal, in its tip frame, the reverse of the other pads'
    mean normal at the posture where it opposes them most, across its distal phalanx (the side of a
    thumb's tip that faces the fingers, as the shipped hand's config gives by hand; its closing side
    may face across the palm), its point where its distal link reaches farthest that way. A pad the
    config gives, a hand of fewer than 3 fingers, none or more than one that opposes (alike fingers
    around an axis: TriFinger, the D'Claw), a facing direction mostly along the phalanx
    (``SIDEWAYS``): ``pads`` unchanged."""
    if len(pads) < 3 or len(pads) != len(robot.fingers):
        return pads
    try:
        o, opposition, best = _opposing(robot, pads)
    except ConfigError:
        return pads
    name = list(robot.fingers)[o]
    if robot.cfg.fingers[name].pad is not None or np.sort(opposition)[1] < OPPOSE_MAX:  # given; or alike fingers
        return pads
    q = _postures(robot)[best]
    normals = _pad_normals(robot, q, pads)
    facing = -np.delete(normals, o, axis=0).mean(axis=0)
    names, frames = _palm_frames(robot, q)
    T = frames[names.index(robot.cfg.fingers[name].tip)]
    local = T[:3, :3].T @ facing
    chain = robot.fingers[name].chain  # its distal axis: from its last joint to the tip, tip frame
    joint = frames[names.index(robot.urdf.joints[chain.joint_names[-1]].child), :3, 3]
    axis = T[:3, :3].T @ (T[:3, 3] - joint)
    axis = axis / max(float(np.linalg.norm(axis)), 1e-12)
    side = local - (local @ axis) * axis  # a pad faces sideways off the finger, not out of its end
    if float(np.linalg.norm(side)) < SIDEWAYS * float(np.linalg.norm(local)):
        return pads
    return {**pads, name: derived_pad(robot, name, side / float(np.linalg.norm(side)))}


def hand_axes(robot: _Robot) -> HandAxes:
    """The hand's front, extension and opposing finger (module docstring), from its pads
    (``robot.pads``). :class:`ConfigError` for a hand with fewer than 2 fingers with pads (a
    gripper) or whose pads cannot oppose (every pad facing within 90 degrees of the others' mean)."""
    pads = robot.pads
    _check_hand(robot, pads)
    names = list(robot.fingers)
    postures = _postures(robot)
    tips = robot.fingertips_palm(postures[0]).numpy().astype(np.float64)
    normals = _pad_normals(robot, postures[0], pads)
    o, opposition, _ = _opposing(robot, pads)
    extension = tips.mean(axis=0)
    extension = extension / max(float(np.linalg.norm(extension)), 1e-12)
    lo, hi = (torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in robot.finger_limits)
    front = _knuckle_normal(robot, lo + 0.5 * (hi - lo))
    if front is None:
        mean = np.delete(normals, o, axis=0).mean(axis=0)
        front = mean - (mean @ extension) * extension
    front = _snap(front / max(float(np.linalg.norm(front)), 1e-12))
    dist = np.round(np.linalg.norm(tips - tips[o], axis=1), 9)  # alike fingers' ties: the config's order
    order = (names[o], *(names[k] for k in np.argsort(dist, kind="stable") if k != o))
    return HandAxes(front, extension, names[o], opposition, order, normals, tips)


def default_fingers(robot: _Robot, count: int = DEFAULT_COUNT) -> tuple[str, ...]:
    """The default fingers of a grasp: the opposing finger, then its nearest neighbours, ``count``
    in all (every finger where the hand has fewer) (:func:`hand_axes`)."""
    return hand_axes(robot).order[:count]
