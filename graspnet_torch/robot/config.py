"""Typed robot configuration, read from ``configs/robot/<name>.yaml``.

The YAML keys are those of docs/robots.md; files give lengths in metres and angles in
degrees, the dataclasses hold SI units (metres, radians). See configs/robot/hand.yaml for a
commented example.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.files import read_document
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.robot.kinds import ProblemSchema, robot_kind
from graspnet_torch.robot.meshes import urdf_file
from graspnet_torch.settings import MAX_ANGLE_DEG, MAX_LENGTH_M, clip, number_list, short

__all__ = ["ChainCfg", "PadCfg", "PoseBounds", "RobotCfg", "available_robots", "load_robot_cfg",
           "robot_cfg_from_setting"]


@dataclass(frozen=True)
class PadCfg:
    """A finger's pad as its config gives it (``pad: {link: <link>, point: [x, y, z], normal: [nx, ny, nz]}``):
    a point (m) and an outward unit normal (normalised here) in ``link``'s frame; the link is checked
    against the URDF by :func:`graspnet_torch.robot.pads.finger_pads`."""

    link: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]


@dataclass(frozen=True)
class ChainCfg:
    """A serial chain named by its first and last link.

    Attributes:
        base, tip: link names; a finger's ``base`` defaults to the palm link.
        tip_offset: (x, y, z) of the tip point in the ``tip`` link's frame (m): a fingertip that is
            not a URDF link (``tip: {link: <link>, offset: [x, y, z]}`` in the file).
        pad: a finger's pad (``pad:`` in the file), or None: derived from the URDF
            (:mod:`graspnet_torch.robot.pads`).
    """

    base: str
    tip: str
    tip_offset: tuple[float, float, float] | None = None
    pad: PadCfg | None = None


@dataclass(frozen=True)
class PoseBounds:
    """Box bounds of a 6-D pose ``(x, y, z, rx, ry, rz)``: metres and radians.

    Attributes:
        lower, upper: (6,) float64 arrays.
    """

    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def from_degrees(cls, bounds: Mapping[str, Any], where: str) -> PoseBounds:
        """From ``{min: [x, y, z, rx, ry, rz], max: [...]}`` with angles in degrees."""
        if not isinstance(bounds, Mapping) or set(bounds) != {"min", "max"}:
            raise ConfigError(f"{where}: expected a mapping with keys 'min' and 'max'")
        arrays = []
        for key in ("min", "max"):
            xyz = number_list(bounds[key], 6, f"{where}.{key}", ConfigError, -MAX_ANGLE_DEG, MAX_ANGLE_DEG,
                              "numbers (x, y, z in m, rx, ry, rz in degrees)")
            arr = np.asarray(xyz, dtype=np.float64)
            if np.any(np.abs(arr[:3]) > MAX_LENGTH_M):
                raise ConfigError(f"{where}.{key}: x, y, z must lie within +-{MAX_LENGTH_M:g} m, got {short(xyz)}")
            arrays.append(np.concatenate([arr[:3], np.radians(arr[3:])]))
        lower, upper = arrays
        bad = np.nonzero(lower > upper)[0]
        if bad.size:
            names = ("x", "y", "z", "rx", "ry", "rz")
            raise ConfigError(f"{where}: min > max for {', '.join(names[i] for i in bad)}")
        return cls(lower, upper)

    def to_degrees(self) -> dict[str, list[float]]:
        conv = np.array([1, 1, 1, 180 / math.pi, 180 / math.pi, 180 / math.pi])
        return {"min": (self.lower * conv).tolist(), "max": (self.upper * conv).tolist()}


@dataclass(frozen=True)
class RobotCfg:
    """A robot: its URDF and the named links that give it its structure.

    Attributes:
        name: robot name.
        urdf: absolute path of the URDF.
        palm_link: the link whose pose the configuration network chooses (hand) or the arm moves.
        fingers: finger name -> chain from its fixed base frame to its fingertip; thumb first.
        palm_bounds: a free hand's world box of palm poses, searched by problems that say
            ``palm_bounds: robot`` (the paper's Table 1 for ``hand``); None: no such box (problems
            without ``palm_bounds`` search a space built from their contacts).
        arm: chain from the arm's base to ``palm_link`` (arm_hand, manus), or None.
        mobile_base: chain from the world to the platform carrying the arm (manus), or None.
        gripper_points: the two marked point links of a gripper (manus), or ().
        home: joint name -> home value as written in the file (degrees for revolute joints, metres
            for prismatic ones), for pictures; missing joints are 0.
        wrist: a free hand's movable joints between the URDF root and ``palm_link`` -> the value
            each is held at, as written (degrees or metres); missing joints are 0.
        hand: the free hand an arm carries (a robot's name or config file): ``contacts: auto``
            chooses contact sets with it and the arm reaches them (its fingers must be this robot's).
        checkpoint: the FCNN checkpoint of its fingers, when it is not ``checkpoints/<name>/fcnn.pt``
            (``arm_hand`` reuses the hand's: same finger chains); a config given by path defaults
            to ``<its folder>/<name>.fcnn.pt``.
        floor: height (m, world z) of the floor the robot stands on, an obstacle of every problem
            (a mobile robot: ``manus``), or None.
        self_collision: count collisions between the robot's own links (pairs that are neither
            adjacent nor already touching at the home posture; :mod:`graspnet_torch.collision`).
        solver_defaults: group ('srv', 'reward', 'solver') -> settings this robot uses unless the
            user sets them (the ACNN's section 6.3 parameters for ``arm_hand``), as written; the
            solver checks them against the groups' dataclasses
            (:func:`graspnet_torch.solver.defaults.check_solver_defaults`).
        source: the file this came from, for error messages.
        folder: the config file's folder (a config given by path), where its URDF's meshes may
            also lie; None for a shipped config.
        allow_outside_paths: its URDF and the URDF's meshes may lie anywhere (else within the
            URDF's folder, ``folder``, the repository and installed packages).
    """

    name: str
    urdf: Path
    palm_link: str
    fingers: dict[str, ChainCfg] = field(default_factory=dict)
    palm_bounds: PoseBounds | None = None
    arm: ChainCfg | None = None
    mobile_base: ChainCfg | None = None
    gripper_points: tuple[str, ...] = ()
    home: dict[str, float] = field(default_factory=dict)
    wrist: dict[str, float] = field(default_factory=dict)
    checkpoint: Path | None = None
    hand: str | None = None
    floor: float | None = None
    self_collision: bool = False
    solver_defaults: dict[str, dict[str, Any]] = field(default_factory=dict)
    source: str = "<memory>"
    folder: Path | None = None
    allow_outside_paths: bool = False

    @property
    def mesh_roots(self) -> tuple[Path, ...]:
        """Folders the URDF's meshes may lie in besides the URDF's own (see
        :func:`graspnet_torch.robot.meshes.mesh_roots`)."""
        return (self.folder,) if self.folder is not None else ()

    @property
    def kind(self) -> str:
        """'hand' (a free palm with fingers), 'arm_hand' (fingers on an arm) or 'gripper' (a body
        chain with two marked gripper points, no fingers)."""
        if not self.fingers:
            return "gripper"
        return "arm_hand" if self.arm is not None else "hand"

    @property
    def problem_schema(self) -> ProblemSchema:
        """The kind-specific keys of this robot's problem files (its kind's row:
        :func:`graspnet_torch.robot.kinds.robot_kind`)."""
        return robot_kind(self).schema

    @property
    def cli_name(self) -> str:
        """How to name this robot on a command line: its name when shipped, else its file."""
        return self.name if self.source == str(configs_dir() / "robot" / f"{self.name}.yaml") or \
            not self.source.endswith((".yaml", ".yml")) else self.source

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "<memory>", folder: Path | None = None,
                     allow_outside_paths: bool = False) -> RobotCfg:
        """Validate a parsed robot config (YAML mapping, Hydra ``DictConfig`` as a container).

        ``urdf`` is looked up in ``folder`` (the config file's folder, when it has one) and then the
        repository root; it must stay within those, or an installed Python package, unless
        ``allow_outside_paths``. ``urdf: package://<python package>/<path>`` names a file inside an
        installed Python package (found without importing it; see :func:`~graspnet_torch.robot.meshes.urdf_file`).
        """
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: a robot config must be a mapping, got {type(data).__name__}")
        known = {"name", "urdf", "palm_link", "fingers", "palm_bounds", "arm", "mobile_base",
                 "gripper_points", "home", "description", "checkpoint", "solver_defaults",
                 "floor", "self_collision", "hand", "wrist"}
        unknown = sorted(clip(k, 40) for k in data if k not in known)
        if unknown:
            raise ConfigError(f"{source}: unknown key(s) {', '.join(unknown[:5])} "
                              f"(expected {', '.join(sorted(known))})")
        for key in ("name", "urdf", "palm_link"):
            if not isinstance(data.get(key), str) or not data[key]:
                raise ConfigError(f"{source}: '{key}' must be a non-empty string")
        fingers = {}
        for fname, chain in _mapping(data, "fingers", source, "finger names to {base, tip}").items():
            if not isinstance(fname, str) or not fname:
                raise ConfigError(f"{source}: fingers: a finger name must be a string, got {short(fname)}")
            fingers[fname] = _finger(chain, f"{source}: fingers.{clip(fname, 40)}", data["palm_link"])
        bounds = data.get("palm_bounds")
        palm_bounds = PoseBounds.from_degrees(bounds, f"{source}: palm_bounds") if bounds is not None else None
        arm = _chain(data["arm"], f"{source}: arm") if data.get("arm") is not None else None
        base = _chain(data["mobile_base"], f"{source}: mobile_base") if data.get("mobile_base") is not None else None
        points = () if data.get("gripper_points") is None else data["gripper_points"]
        if points != () and (not isinstance(points, list | tuple) or len(points) != 2
                       or not all(isinstance(p, str) for p in points)):
            raise ConfigError(f"{source}: 'gripper_points' must list two link names")
        if not fingers and not points:
            raise ConfigError(f"{source}: a robot needs 'fingers' or 'gripper_points'")
        home, wrist = _joint_values(data, "home", source), _joint_values(data, "wrist", source)
        if wrist and arm is not None:
            raise ConfigError(f"{source}: 'wrist' holds a free hand's wrist joints; with 'arm' they are arm joints")
        bases = (Path(folder), repo_root()) if folder is not None else (repo_root(),)
        urdf = urdf_file(data["urdf"], f"{source}: urdf", bases, allow_outside_paths)
        checkpoint = None
        if data.get("checkpoint") is not None:
            raw = data["checkpoint"]
            if not isinstance(raw, str) or not raw or len(raw) > 4096:
                raise ConfigError(f"{source}: 'checkpoint' must be a file path, got {short(raw)}")
            checkpoint = Path(raw) if Path(raw).is_absolute() else bases[0] / raw
        elif folder is not None:  # a robot config given by path: its FCNN lives beside it
            checkpoint = Path(folder) / f"{data['name']}.fcnn.pt"
        hand = data.get("hand")
        if hand is not None and (not isinstance(hand, str) or not hand or len(hand) > 4096 or data.get("arm") is None):
            raise ConfigError(f"{source}: 'hand' (a robot with an arm: its free hand, name or file) got {short(hand)}")
        if hand is not None and hand.endswith((".yaml", ".yml")) and not Path(hand).is_absolute():
            hand = str(bases[0] / hand)
        floor = data.get("floor")
        if floor is not None:
            floor = number_list([floor], 1, f"{source}: floor", ConfigError, -100.0, 100.0, "number (m)")[0]
        self_collision = data.get("self_collision", False)
        if not isinstance(self_collision, bool):
            raise ConfigError(f"{source}: 'self_collision' must be true or false, got {short(self_collision)}")
        return cls(name=data["name"], urdf=urdf, palm_link=data["palm_link"], fingers=fingers,
                   palm_bounds=palm_bounds, arm=arm, mobile_base=base, gripper_points=tuple(points),
                   home=home, wrist=wrist, checkpoint=checkpoint, hand=hand, floor=floor, self_collision=self_collision,
                   solver_defaults=_solver_defaults(data, source), source=source,
                   folder=Path(folder) if folder is not None else None, allow_outside_paths=allow_outside_paths)


def _finger(value: Any, where: str, palm: str) -> ChainCfg:
    """``{base: <link>, tip: <link>}``; ``base`` may be left out (the palm), ``tip`` may be
    ``{link: <link>, offset: [x, y, z]}``; an optional ``pad`` (:func:`_pad`)."""
    if not isinstance(value, Mapping) or "tip" not in value or not set(value) <= {"base", "tip", "pad"}:
        raise ConfigError(f"{where}: expected {{base: <link>, tip: <link>}} or {{tip: {{link: <link>, offset: "
                          f"[x, y, z]}}}}, got {short(value)}")
    base = value.get("base", palm)
    if not isinstance(base, str) or not base:
        raise ConfigError(f"{where}: base must be a link name, got {short(base)}")
    tip, offset = value["tip"], None
    if isinstance(tip, Mapping):
        if set(tip) != {"link", "offset"} or not isinstance(tip["link"], str) or not tip["link"]:
            raise ConfigError(f"{where}.tip: expected a link name or {{link: <link>, offset: [x, y, z]}}, "
                              f"got {short(tip)}")
        xyz = number_list(tip["offset"], 3, f"{where}.tip.offset", ConfigError, -MAX_LENGTH_M, MAX_LENGTH_M,
                          "numbers (m, in the tip link's frame)")
        tip, offset = tip["link"], (float(xyz[0]), float(xyz[1]), float(xyz[2]))
    elif not isinstance(tip, str) or not tip:
        raise ConfigError(f"{where}: tip must be a link name or {{link: <link>, offset: [x, y, z]}}, got {short(tip)}")
    return ChainCfg(base, tip, offset, None if value.get("pad") is None else _pad(value["pad"], f"{where}.pad"))


def _pad(value: Any, where: str) -> PadCfg:
    """``{link: <link>, point: [x, y, z], normal: [nx, ny, nz]}``: the normal must not be zero."""
    if not isinstance(value, Mapping) or set(value) != {"link", "point", "normal"} \
            or not isinstance(value["link"], str) or not value["link"]:
        raise ConfigError(f"{where}: expected {{link: <link>, point: [x, y, z], normal: [nx, ny, nz]}}, "
                          f"got {short(value)}")
    point = number_list(value["point"], 3, f"{where}.point", ConfigError, -MAX_LENGTH_M, MAX_LENGTH_M,
                        "numbers (m, in the link's frame)")
    normal = np.asarray(number_list(value["normal"], 3, f"{where}.normal", ConfigError, -1e6, 1e6,
                                    "numbers (a direction in the link's frame)"), dtype=np.float64)
    norm = float(np.linalg.norm(normal))
    if not norm > 1e-9:
        raise ConfigError(f"{where}.normal: must not be zero, got {short(value['normal'])}")
    n = normal / norm
    return PadCfg(value["link"], (float(point[0]), float(point[1]), float(point[2])),
                  (float(n[0]), float(n[1]), float(n[2])))


def _chain(value: Any, where: str) -> ChainCfg:
    if not isinstance(value, Mapping) or set(value) != {"base", "tip"}:
        raise ConfigError(f"{where}: expected {{base: <link>, tip: <link>}}, got {short(value)}")
    if not all(isinstance(value[k], str) and value[k] for k in ("base", "tip")):
        raise ConfigError(f"{where}: base and tip must be link names")
    return ChainCfg(value["base"], value["tip"])


def _mapping(data: Mapping[str, Any], key: str, source: str, what: str) -> Mapping:
    """``data[key]`` that must be a mapping (``what`` it maps); missing or null: empty."""
    raw = {} if data.get(key) is None else data[key]
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{source}: '{key}' must map {what}")
    return raw


def _joint_values(data: Mapping[str, Any], key: str, source: str) -> dict[str, float]:
    """``data[key]``: joint names to numbers (degrees or metres, as written); missing: empty."""
    return {clip(joint, 80): number_list([value], 1, f"{source}: {key}.{clip(joint, 40)}", ConfigError,
                                         -MAX_ANGLE_DEG, MAX_ANGLE_DEG, "number")[0]
            for joint, value in _mapping(data, key, source, "joint names to numbers").items()}


def available_robots() -> list[str]:
    """Names of the robot configs shipped under ``configs/robot/``."""
    return sorted(p.stem for p in (configs_dir() / "robot").glob("*.yaml"))


def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except OSError:  # a name too long for the file system
        return False


def load_robot_cfg(name_or_path: str | Path, allow_outside_paths: bool = False) -> RobotCfg:
    """A robot config by name (``configs/robot/<name>.yaml``) or by path to a YAML file; its URDF
    and meshes may lie anywhere only with ``allow_outside_paths``."""
    text = str(name_or_path)
    if not text or len(text) > 4096 or "\x00" in text:
        raise ConfigError(f"unknown robot '{clip(text, 80)}': expected one of {', '.join(available_robots())}")
    path = Path(text)
    by_path = text.endswith((".yaml", ".yml")) or os.sep in text
    if not by_path:
        path = configs_dir() / "robot" / f"{text}.yaml"
        if not _is_file(path):
            raise ConfigError(f"unknown robot '{clip(text, 80)}': expected one of {', '.join(available_robots())} "
                              f"(configs/robot/) or a path to a robot YAML file")
    data = read_document(path, "robot config", ConfigError)
    shipped = path.resolve().parent == (configs_dir() / "robot").resolve()
    return RobotCfg.from_mapping(data, source=str(path), folder=None if shipped else path.resolve().parent,
                                 allow_outside_paths=allow_outside_paths)


def robot_cfg_from_setting(value: Any, allow_outside_paths: bool = False) -> RobotCfg | None:
    """The robot of a job's ``robot`` setting: a name or a YAML path (str), the ``robot`` group as
    Hydra composed it (a mapping, overrides included), ``robot=PATH`` on the command line
    (``{name, config}``, see :func:`graspnet_torch.jobs.cli.robot_path_overrides`), or None.
    ``allow_outside_paths``: the job's setting of that name (its URDF and meshes anywhere)."""
    if value is None:
        return None
    if isinstance(value, str):
        return load_robot_cfg(value, allow_outside_paths)
    if isinstance(value, Mapping) and "config" in value and "urdf" not in value:
        extra = sorted(set(value) - {"name", "config"})
        if extra:
            raise ConfigError(f"robot={clip(str(value['config']), 200)}: robot.{extra[0]} cannot be overridden for a "
                              f"robot given by path; edit the file")
        return load_robot_cfg(str(value["config"]), allow_outside_paths)
    if isinstance(value, Mapping):
        return RobotCfg.from_mapping(value, source=f"robot={clip(str(value.get('name')), 80)}",
                                     allow_outside_paths=allow_outside_paths)
    raise ConfigError(f"robot: expected a robot name or a path to a robot YAML file, got {short(value)}")


SOLVER_DEFAULT_GROUPS = ("srv", "reward", "solver")  # the settings groups a robot's solver_defaults may set


def _solver_defaults(data: Mapping[str, Any], source: str) -> dict[str, dict[str, Any]]:
    """The robot's ``solver_defaults``: each of :data:`SOLVER_DEFAULT_GROUPS` a mapping of settings,
    kept as written (their values are checked against the groups' settings where the solver reads
    them: :func:`graspnet_torch.solver.defaults.check_solver_defaults`)."""
    raw = data.get("solver_defaults")
    if raw is None:
        return {}
    if not isinstance(raw, Mapping) or any(k not in SOLVER_DEFAULT_GROUPS for k in raw):
        raise ConfigError(f"{source}: 'solver_defaults' must map srv, reward or solver to settings")
    out = {}
    for group, values in raw.items():
        if not isinstance(values, Mapping):
            raise ConfigError(f"{source}: solver_defaults.{group}: expected a mapping of settings")
        out[group] = dict(values)
    return out
