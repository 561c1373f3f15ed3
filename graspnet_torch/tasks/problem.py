"""Grasp problems: a robot, an object, one contact per finger (problem files, shipped tasks).

A problem file (YAML or JSON; docs/objects.md) is validated completely before any
work starts; every refusal is a :class:`~graspnet_torch.errors.ProblemError` with one line that
names the file and the offending entry. Files give angles in degrees; the dataclasses hold
metres and radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from graspnet_torch.errors import ProblemError
from graspnet_torch.files import read_document
from graspnet_torch.paths import configs_dir
from graspnet_torch.robot.config import PoseBounds, RobotCfg
from graspnet_torch.robot.shape import Shape, numbers, pose_degrees, unknown_keys
from graspnet_torch.robot.transforms import rpy_to_matrix_np
from graspnet_torch.settings import MAX_ANGLE_DEG, clip, number_list, short
from graspnet_torch.tasks.auto_contacts import AUTO_KEYS, AutoContacts, auto_contacts
from graspnet_torch.tasks.problem_sections import joint_bounds_of, palm_bounds_of, robot_of
from graspnet_torch.tasks.shapes import check_free_contacts, obstacles_of

__all__ = ["Contact", "GraspProblem", "ReferencePosture", "Shape", "available_tasks"]

KNOWN_KEYS = {"robot", "object", "contacts", "points", "approach", "palm_bounds", "bounds", "obstacles", "name",
              "description", "reference", "start", "notes", *AUTO_KEYS}

KIND_KEYS = {"contacts": "one point per finger", "points": "a gripper's two object points",
             "approach": "a gripper's approach configuration", "palm_bounds": "a free hand's palm box",
             "bounds": "an arm's joint ranges", "reference": "a reference posture",
             "start": "the configuration a reach motion starts from (robots with a body)"}
"""The problem keys that only some kinds of robot take (``RobotCfg.problem_schema``), with what they are."""
REFERENCE_PLACEMENT = {"palm_pose": "[x, y, z, rx, ry, rz]", "arm_joints": "{joint: deg}"}


def _joint_values(raw: Any, where: str) -> dict[str, float] | None:
    """A mapping URDF joint name -> value as written (metres, degrees), or None; checked for
    form and range here (the names and limits against the robot where it is used)."""
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or not raw or not all(isinstance(k, str) for k in raw):
        raise ProblemError(f"{where}: expected a mapping joint name -> value (m, degrees)")
    out = {}
    for name, value in raw.items():
        key = f"{where}.{clip(name, 40)}"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProblemError(f"{key}: expected a number (m, degrees), got {short(value)}")
        if not (math.isfinite(value) and -MAX_ANGLE_DEG <= value <= MAX_ANGLE_DEG):
            raise ProblemError(f"{key}: {short(value)} is not a finite number within [{-MAX_ANGLE_DEG:g}, "
                               f"{MAX_ANGLE_DEG:g}]")
        out[name] = float(value)
    return out


def _check_texts(data: Mapping, source: str) -> None:
    for key in ("name", "description"):
        if data.get(key) is not None and (not isinstance(data[key], str) or len(data[key]) > 10_000):
            raise ProblemError(f"{source}: '{key}' must be a string (at most 10000 characters)")
        if isinstance(data.get(key), str) and not data[key].isascii():
            try:
                data[key].encode("utf-8")
            except UnicodeEncodeError as exc:  # a lone surrogate, such as the escape \udcff in JSON
                raise ProblemError(f"{source}: '{key}' is not UTF-8 text (a lone surrogate "
                                   f"{data[key][exc.start]!a} at character {exc.start})") from None


@dataclass(frozen=True)
class Contact:
    """One contact: the finger that touches it and its position in the object frame (m)."""

    finger: str
    position: np.ndarray


def _check_kind_keys(data: Mapping, source: str, robot: str, robot_cfg: RobotCfg) -> None:
    """Refuse the keys of another kind of robot (:data:`KIND_KEYS` that the robot's problems do not
    take; ``contacts: auto`` suits any kind)."""
    schema = robot_cfg.problem_schema
    for key in KIND_KEYS:  # the keys of another kind of robot
        chosen = key == "contacts" and data.get(key) == "auto"  # contacts: auto: any kind of robot
        if data.get(key) is not None and key not in schema.keys and not chosen:
            raise ProblemError(f"{source}: '{key}' ({KIND_KEYS[key]}) does not apply to robot '{robot}' "
                               f"({robot_cfg.kind}), whose problems give {', '.join(schema.keys)}")


def _contacts_of(data: Mapping, source: str, robot: str, fingers: list[str]) -> list[Contact]:
    """The problem's ``contacts``: 2 to len(fingers) entries {finger, position (m, object frame)},
    at most one per finger."""
    raw = data.get("contacts")
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        raise ProblemError(f"{source}: 'contacts' must be a list of {{finger, position}}")
    if not 2 <= len(raw) <= len(fingers):
        raise ProblemError(f"{source}: contacts: need 2 to {len(fingers)} contacts (at most one per finger of "
                           f"'{robot}'), got {len(raw)}")
    contacts, seen = [], {}
    for k, entry in enumerate(raw):
        where = f"{source}: contacts[{k}]"
        if not isinstance(entry, Mapping) or unknown_keys(entry, {"finger", "position"}) or "finger" not in entry:
            raise ProblemError(f"{where}: expected {{finger: <name>, position: [x, y, z]}}, got {short(entry)}")
        finger = entry["finger"]
        if not isinstance(finger, str) or finger not in fingers:
            raise ProblemError(f"{where}.finger: unknown finger {short(finger)} for robot '{robot}' (fingers: "
                               f"{', '.join(fingers)})")
        if finger in seen:
            raise ProblemError(f"{where}.finger: finger '{finger}' appears twice (contacts[{seen[finger]}] "
                               f"and contacts[{k}])")
        seen[finger] = k
        contacts.append(Contact(finger, numbers(entry.get("position"), 3, f"{where}.position",
                                                 "numbers (x, y, z in metres)")))
    return contacts


@dataclass(frozen=True)
class ReferencePosture:
    """A known posture that reaches every contact (shipped tasks carry one, to show that the task
    is reachable): palm pose (6,) in m/rad (a free hand; None for an arm, whose palm its joints
    place), finger joints per finger and, for an arm, its joints by name, in radians."""

    palm_pose: np.ndarray | None
    joints: dict[str, np.ndarray]
    arm_joints: dict[str, float] | None = None


@dataclass(frozen=True)
class GraspProblem:
    """A grasp problem: which robot, where each finger must touch, within which palm bounds.

    Attributes:
        robot: robot name (``configs/robot/<robot>.yaml``).
        contacts: one per finger (2 to the number of fingers), positions in the object frame.
        object: the grasped object (optional; pictures and collisions); its pose places the
            object frame in the world. Without an object, the object frame is the world.
        palm_bounds: search space of the palm pose (a free hand): a box in the world, ``"robot"``
            (the robot config's box, as the paper's tasks use), or None: built from the contacts
            (any orientation; :mod:`graspnet_torch.solver.search_space`).
        joint_bounds: robots with an arm: (min, max) of its joints in chain order, as written
            (degrees for revolute joints, metres for prismatic ones), or None for the joint limits.
        obstacles: other shapes in the world.
        name, description: for tasks.
        reference: a posture known to solve the problem (optional).
        points: a gripper robot (MANUS, section 7): the two object points (2, 3), object frame,
            metres, that the gripper's two marked points must meet (either pairing); else None.
        approach: a gripper robot: the configuration the user reached, by URDF joint name as
            written (metres, degrees); the search stays near it. None: the robot's search space.
        start: a robot with a body: the configuration its reach motion starts from, by URDF joint
            name as written (metres, degrees; joints left out at home). None: the home posture.
        auto: ``contacts: auto``: the fingers and number of grasps to choose contacts for on the
            object (:mod:`graspnet_torch.tasks.auto_contacts`; ``contacts`` is then empty); else None.
        source: where it came from, for messages.
    """

    robot: str
    contacts: tuple[Contact, ...]
    object: Shape | None = None
    palm_bounds: PoseBounds | Literal["robot"] | None = None
    obstacles: tuple[Shape, ...] = ()
    name: str | None = None
    description: str | None = None
    reference: ReferencePosture | None = None
    source: str = "<memory>"
    robot_cfg: RobotCfg | None = field(default=None, repr=False, compare=False)
    joint_bounds: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False)
    points: np.ndarray | None = field(default=None, compare=False)
    approach: dict[str, float] | None = field(default=None, compare=False)
    start: dict[str, float] | None = field(default=None, compare=False)
    auto: AutoContacts | None = field(default=None, compare=False)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_mapping(cls, data: Any, source: str = "<memory>", robot_cfg: RobotCfg | None = None,
                     folder: Path | None = None, allow_outside_paths: bool = False) -> GraspProblem:
        """Validate a parsed problem; ``robot_cfg`` overrides loading ``configs/robot/<robot>.yaml``.

        ``folder`` is the problem file's folder: mesh paths are looked up there first. Every number
        must be finite and within the physical ranges of :mod:`graspnet_torch.settings` (10 m,
        360 degrees).
        """
        if not isinstance(data, Mapping):
            raise ProblemError(f"{source}: a problem must be a mapping with robot and contacts, got "
                               f"{type(data).__name__}")
        unknown = unknown_keys(data, KNOWN_KEYS)
        if unknown:
            raise ProblemError(f"{source}: unknown key(s) {', '.join(unknown[:5])} "
                               f"(expected {', '.join(sorted(KNOWN_KEYS))})")
        robot, robot_cfg = robot_of(data, source, robot_cfg, folder)
        _check_kind_keys(data, source, robot, robot_cfg)
        auto = auto_contacts(data, source, robot_cfg)  # contacts: auto (tasks/auto_contacts.py)
        if auto is not None:
            obj = Shape.from_mapping(data["object"], f"{source}: object", folder=folder,
                                     allow_outside_paths=allow_outside_paths)
            _check_texts(data, source)
            obstacles = obstacles_of(data, source, {"folder": folder, "allow_outside_paths": allow_outside_paths})
            return cls(robot=robot, contacts=(), object=obj, name=data.get("name"), description=data.get("description"),
                       source=source, robot_cfg=robot_cfg, auto=auto, obstacles=obstacles)
        if robot_cfg.problem_schema.targets == "points":  # a gripper with two marked points (MANUS): no contacts
            return cls._gripper_problem(data, source, robot, robot_cfg, folder, allow_outside_paths)
        contacts = _contacts_of(data, source, robot, list(robot_cfg.fingers))
        shape = {"folder": folder, "allow_outside_paths": allow_outside_paths}
        obj = None
        if data.get("object") is not None:
            obj = Shape.from_mapping(data["object"], f"{source}: object", **shape)
        bounds = palm_bounds_of(data, source, robot, robot_cfg)
        joint_bounds = joint_bounds_of(data, source)
        obstacles = obstacles_of(data, source, shape)
        reference = cls._reference(data.get("reference"), contacts, robot_cfg, source)
        if obstacles:
            check_free_contacts(obstacles, [c.finger for c in contacts], np.stack([c.position for c in contacts]), obj,
                                source)
        _check_texts(data, source)
        return cls(robot=robot, contacts=tuple(contacts), object=obj, palm_bounds=bounds, obstacles=obstacles,
                   name=data.get("name"), description=data.get("description"), reference=reference,
                   source=source, robot_cfg=robot_cfg, joint_bounds=joint_bounds,
                   start=_joint_values(data.get("start"), f"{source}: start"))

    @classmethod
    def _gripper_problem(cls, data: Mapping, source: str, robot: str, robot_cfg: RobotCfg, folder: Path | None,
                         allow_outside_paths: bool) -> GraspProblem:
        """A MANUS problem (INTERFACE.md): two object points, an object, an optional approach
        configuration and obstacles; no contacts."""
        raw = data.get("points")
        if not isinstance(raw, Sequence) or isinstance(raw, str) or len(raw) != 2:
            n = len(raw) if isinstance(raw, Sequence) and not isinstance(raw, str) else "none"
            raise ProblemError(f"{source}: points: robot '{robot}' needs exactly 2 object points "
                               f"[[x, y, z], [x, y, z]] (metres, object frame), got {n}")
        points = np.stack([numbers(p, 3, f"{source}: points[{k}]") for k, p in enumerate(raw)])
        if np.linalg.norm(points[0] - points[1]) < 1e-4:
            raise ProblemError(f"{source}: points: the two points are at the same place (closer than 0.1 mm): "
                               f"they define no direction")
        shape = {"folder": folder, "allow_outside_paths": allow_outside_paths}
        obj = Shape.from_mapping(data["object"], f"{source}: object", **shape) if data.get("object") is not None \
            else None
        approach = _joint_values(data.get("approach"), f"{source}: approach")
        obstacles = obstacles_of(data, source, shape)
        _check_texts(data, source)
        return cls(robot=robot, contacts=(), object=obj, obstacles=obstacles, name=data.get("name"),
                   description=data.get("description"), source=source, robot_cfg=robot_cfg, points=points,
                   approach=approach, start=_joint_values(data.get("start"), f"{source}: start"))

    def points_world(self) -> np.ndarray:
        """(2, 3) the object points in the world (object pose applied)."""
        if self.points is None:
            raise ValueError(f"{self.source}: not a two-point (gripper) problem")
        if self.object is None:
            return self.points.copy()

        return self.points @ rpy_to_matrix_np(self.object.pose[3:]).T + self.object.pose[:3]

    @staticmethod
    def _reference(data: Any, contacts: list[Contact], robot_cfg: RobotCfg, source: str) -> ReferencePosture | None:
        if data is None:
            return None
        where = f"{source}: reference"
        first = robot_cfg.problem_schema.reference  # what places the palm: palm_pose or arm_joints
        expected = f"{{{first}: {REFERENCE_PLACEMENT[first]}, joints: {{finger: [...]}}}}"
        if not isinstance(data, Mapping) or unknown_keys(data, {first, "joints"}) or len(data) != 2:
            raise ProblemError(f"{where}: expected {expected}")
        if not isinstance(data["joints"], Mapping):
            raise ProblemError(f"{where}.joints: expected a mapping finger -> joint angles (degrees), got "
                               f"{short(data['joints'])}")
        joints = {}
        for finger, values in data["joints"].items():
            if not isinstance(finger, str) or finger not in robot_cfg.fingers:
                raise ProblemError(f"{where}.joints: unknown finger {short(finger)}")
            angles = number_list(values, None, f"{where}.joints.{finger}", ProblemError, -MAX_ANGLE_DEG,
                                 MAX_ANGLE_DEG, "joint angles (degrees)")
            if not angles:
                raise ProblemError(f"{where}.joints.{finger}: expected joint angles (degrees), got []")
            joints[finger] = np.radians(np.asarray(angles, dtype=np.float64))
        missing = [c.finger for c in contacts if c.finger not in joints]
        if missing:
            raise ProblemError(f"{where}.joints: missing finger(s) {', '.join(missing)}")
        if first == "arm_joints":
            raw = data["arm_joints"]
            if not isinstance(raw, Mapping) or not all(isinstance(k, str) for k in raw):
                raise ProblemError(f"{where}.arm_joints: expected a mapping joint name -> degrees")
            values = number_list(list(raw.values()), None, f"{where}.arm_joints", ProblemError, -MAX_ANGLE_DEG,
                                 MAX_ANGLE_DEG, "joint angles (degrees)")
            return ReferencePosture(None, joints, {k: math.radians(v) for k, v in zip(raw, values, strict=True)})
        return ReferencePosture(pose_degrees(data["palm_pose"], f"{where}.palm_pose"), joints)

    @classmethod
    def from_file(cls, path: str | Path, robot_cfg: RobotCfg | None = None,
                  allow_outside_paths: bool = False) -> GraspProblem:
        """Read and validate a problem file (``.json``, else YAML; at most 1 MiB, UTF-8, no YAML
        aliases); mesh paths in it are relative to its folder (see :meth:`from_mapping`)."""
        data = read_document(path, "problem file", ProblemError)
        path = Path(path)
        return cls.from_mapping(data, source=clip(str(path), 200), robot_cfg=robot_cfg, folder=path.resolve().parent,
                                allow_outside_paths=allow_outside_paths)

    @classmethod
    def from_task(cls, name: str, robot_cfg: RobotCfg | None = None) -> GraspProblem:
        """A task shipped under ``configs/task/<name>.yaml``."""
        path = configs_dir() / "task" / f"{name}.yaml"
        if not path.is_file():
            raise ProblemError(f"unknown task '{name}': expected one of {', '.join(available_tasks())} (configs/task/)")
        problem = cls.from_file(path, robot_cfg=robot_cfg)
        return problem if problem.name else cls(**{**problem.__dict__, "name": name})

    # ------------------------------------------------------------------ views
    @property
    def fingers(self) -> tuple[str, ...]:
        return tuple(c.finger for c in self.contacts)

    def bounds(self) -> PoseBounds | None:
        """The palm search space as a box in the world: the problem's, or the robot config's
        (``palm_bounds: robot``); None when it is built from the contacts (the default)."""
        if self.palm_bounds == "robot":
            return self.robot_cfg.palm_bounds
        return self.palm_bounds

    def moved(self, transform: np.ndarray) -> GraspProblem:
        """The same problem moved and turned by a rigid transform (4, 4) of the world: the object,
        the obstacles and (without an object) the contacts; a box of palm poses cannot turn with
        it, so explicit ``palm_bounds`` are dropped (the moved problem's search space is built
        from its contacts)."""
        from dataclasses import replace

        contacts = self.contacts
        if self.object is None:
            contacts = tuple(Contact(c.finger, transform[:3, :3] @ c.position + transform[:3, 3]) for c in contacts)
        points = self.points
        if self.object is None and points is not None:
            points = points @ transform[:3, :3].T + transform[:3, 3]
        return replace(self, contacts=contacts, object=None if self.object is None else self.object.moved(transform),
                       obstacles=tuple(o.moved(transform) for o in self.obstacles), points=points, palm_bounds=None,
                       reference=None)

    def contacts_object(self) -> np.ndarray:
        """(F, 3) contact positions in the object frame ((0, 3) for a two-point gripper problem)."""
        if not self.contacts:
            return np.zeros((0, 3))
        return np.stack([c.position for c in self.contacts])

    def contacts_world(self) -> np.ndarray:
        """(F, 3) contact positions in the world (object pose applied)."""
        pts = self.contacts_object()
        if self.object is None:
            return pts

        return pts @ rpy_to_matrix_np(self.object.pose[3:]).T + self.object.pose[:3]

    def to_mapping(self) -> dict:
        """The problem as a problem-file mapping (degrees)."""
        out: dict[str, Any] = {"robot": self.robot}
        if self.name:
            out["name"] = self.name
        if self.object is not None:
            out["object"] = self.object.to_mapping()
        out["contacts"] = [{"finger": c.finger, "position": c.position.tolist()} for c in self.contacts]
        if self.palm_bounds is not None:
            out["palm_bounds"] = "robot" if self.palm_bounds == "robot" else self.palm_bounds.to_degrees()
        if self.obstacles:
            out["obstacles"] = [o.to_mapping() for o in self.obstacles]
        if self.start:
            out["start"] = dict(self.start)
        return out



def available_tasks() -> list[str]:
    return sorted(p.stem for p in (configs_dir() / "task").glob("*.yaml"))
