"""``contacts: auto``: a problem that gives an object and a hand and lets the project choose the
contacts on the object's surface (:func:`graspnet_torch.synthesis.synthesize_grasps`).

A problem file::

    robot: hand
    object: {shape: mesh, size: [mug.obj], pose: [0, 0, 0.2, 0, 0, 0]}   # or a box, cylinder, sphere
    contacts: auto
    fingers: [thumb, index, middle]   # the fingers that touch; or a number: the first n fingers
                                      # in the robot's order (thumb first); default 3 (or all, if fewer);
                                      # or, instead, n_fingers: 3 (the same as fingers: 3)
    grasps: 5                         # how many grasps to return, best first (1-100; default 5)

A free hand, or a hand on an arm whose robot config names the free hand (``hand:``: the contact
sets are drawn with it, then the arm reaches them). A gripper with two marked points (MANUS)
says ``points: auto`` (or ``contacts: auto``; its ``points`` chosen: two antipodal points as far
apart as its jaws), with ``grasps`` and its ``obstacles`` (a table). ``fingers`` and ``grasps`` apply only to
``contacts: auto`` (``grasps`` to ``points: auto``); obstacles (a table) are kept clear of.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.config import RobotCfg

__all__ = ["AUTO_KEYS", "DEFAULT_FINGERS", "DEFAULT_GRASPS", "MAX_GRASPS", "AutoContacts", "auto_contacts",
           "contact_fingers"]

AUTO_KEYS = ("fingers", "n_fingers", "grasps")  # the keys only ``contacts: auto`` takes
DEFAULT_FINGERS = 3  # the first three fingers (thumb, index, middle on the shipped hand)
DEFAULT_GRASPS = 5
MAX_GRASPS = 100


@dataclass(frozen=True)
class AutoContacts:
    """What a ``contacts: auto`` problem asks for.

    Attributes:
        fingers: the fingers that touch the object, in the robot's finger order (a gripper: none).
        grasps: how many grasps to return, best first.
    """

    fingers: tuple[str, ...]
    grasps: int = DEFAULT_GRASPS


def _count(value: Any, where: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ProblemError(f"{where}: expected a whole number from {lo} to {hi}, got {value!r}"[:300])
    return value


def auto_contacts(data: Mapping, source: str, robot_cfg: RobotCfg) -> AutoContacts | None:
    """The :class:`AutoContacts` of a parsed problem whose ``contacts`` is ``auto``; None for one
    that gives its contacts (where ``fingers`` / ``grasps`` are refused). Checks the robot's kind,
    the object, the fingers (names of the robot's fingers, each once, at least 2; or a count) and
    the number of grasps: :class:`ProblemError`, one line naming the key."""
    key = robot_cfg.problem_schema.targets  # contacts (fingers) or points (a gripper's two)
    if data.get(key) != "auto" and data.get("contacts") == "auto":  # a gripper's contacts: auto is its points: auto
        key = "contacts"
    if data.get(key) != "auto":
        given = [k for k in AUTO_KEYS if data.get(k) is not None]
        if given:
            raise ProblemError(f"{source}: {', '.join(given)}: only with '{key}: auto' (the project chooses the "
                               f"{key}); this problem lists its {key}")
        return None
    if data.get("object") is None:
        raise ProblemError(f"{source}: {key}: auto needs an object (the {key} are chosen on its surface)")
    if robot_cfg.problem_schema.targets == "points":  # a gripper: its two marked points; obstacles (a table) allowed
        given = [k for k in ("fingers", "n_fingers") if data.get(k) is not None]
        if given:
            raise ProblemError(f"{source}: {given[0]}: robot '{robot_cfg.name}' grasps with its two marked points")
        return AutoContacts((), _count(data.get("grasps", DEFAULT_GRASPS), f"{source}: grasps", 1, MAX_GRASPS))
    names = list(robot_cfg.fingers)
    if robot_cfg.kind != "hand" and robot_cfg.hand is None:
        raise ProblemError(f"{source}: contacts: auto: robot '{robot_cfg.name}' ({robot_cfg.kind}): contacts are "
                           f"chosen for a free hand, or a hand on an arm whose config names it ('hand:'), so far")
    if data.get("fingers") is not None and data.get("n_fingers") is not None:
        raise ProblemError(f"{source}: fingers and n_fingers: give one (n_fingers: N is fingers: N)")
    key = "n_fingers" if data.get("n_fingers") is not None else "fingers"
    raw = data.get(key, min(DEFAULT_FINGERS, len(names)))
    if key == "n_fingers" and (not isinstance(raw, int) or isinstance(raw, bool)):
        raise ProblemError(f"{source}: n_fingers: expected a number of fingers, got {raw!r}"[:300])
    fingers = contact_fingers(names, raw, robot_cfg.name, f"{source}: {key}")
    grasps = _count(data.get("grasps", DEFAULT_GRASPS), f"{source}: grasps", 1, MAX_GRASPS)
    return AutoContacts(fingers, grasps)


def contact_fingers(names: Sequence[str], raw: Any, robot: str, where: str) -> tuple[str, ...]:
    """The fingers that touch, in the robot's finger order (``names``), from ``raw``: a list of
    two or more of its fingers, each once, or a count (its first n fingers, 2 to all). The one
    check of a fingers setting (a problem file's ``fingers``, the synthesis job's, gt.synthesize_grasps');
    :class:`ProblemError` naming ``where`` otherwise."""
    names = list(names)
    if isinstance(raw, int) and not isinstance(raw, bool):
        if not 2 <= raw <= len(names):
            raise ProblemError(f"{where}: {raw}: robot '{robot}' has {len(names)} fingers ({', '.join(names)}); "
                               f"give 2 to {len(names)}")
        return tuple(names[:raw])
    if isinstance(raw, list | tuple) and all(isinstance(f, str) for f in raw):
        unknown = [f for f in raw if f not in names]
        if unknown:
            raise ProblemError(f"{where}: unknown finger(s) {', '.join(unknown)}"[:200] +
                               f" for robot '{robot}' (fingers: {', '.join(names)})")
        if len(set(raw)) != len(raw) or len(raw) < 2:
            raise ProblemError(f"{where}: need 2 or more different fingers, got {list(raw)}"[:300])
        return tuple(f for f in names if f in raw)
    raise ProblemError(f"{where}: expected a list of finger names or a number, got {raw!r}"[:300])
