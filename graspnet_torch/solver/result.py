"""Grasp results and their JSON form (docs/results.md).

Angles in degrees, lengths in metres, errors in millimetres. The reported errors are recomputed
in float64 from the reported configuration by forward kinematics against the problem's contacts,
so a result can be checked from the URDF alone.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from graspnet_torch.errors import InternalError
from graspnet_torch.io import atomic_write_text

__all__ = ["ERROR_KEYS", "FIELD_ORDER", "GraspResult", "Trajectory", "TrialResult"]


# The result JSON's trial fields in the order they are written (INTERFACE.md): the common core, then
# what an environment adds (a fingered robot: the palm pose, joints and fingertip errors; a robot
# with a body: its arm joints; a gripper: d, the alignment and its points), then the surface contact
# model's (solver/contact.py) and the physics check's.
FIELD_ORDER = ("success", "iterations", "reinforcement", "wall_time_s", "palm_pose", "joints", "fingertip_error_mm",
               "total_error_mm", "collisions", "arm_joints", "distance_mm", "alignment", "gripper_points",
               "contact_model", "pad_distance_mm", "normal_angle_deg", "penetration_mm", "pregrasp", "squeeze",
               "physics")
# The fields a trial may be ranked by (its error_mm), in the order they are looked for: E of eq. 3, a gripper's d.
ERROR_KEYS = ("total_error_mm", "distance_mm")
# A result's own keys; every other top-level key is a field of its reported trial.
_CORE = ("success", "iterations", "reinforcement", "wall_time_s", "collisions")  # TrialResult's own attributes
_RESULT_KEYS = ("robot", "trials", "failure", "problem", "seed", "settings", "trajectory")
_RESULT_ATTRIBUTES = (*_RESULT_KEYS, "outcome", "chosen", "best")  # GraspResult's own


@dataclass
class Trajectory:
    """A reach motion (the result's ``trajectory``).

    Attributes:
        joint_names: URDF joint names (a free hand: ``palm_x`` ... ``palm_rz`` first), in order.
        times: (W,) seconds, increasing from 0.
        positions: (W, n) radians or metres (a free hand's palm: metres, radians).
        revolute: (n,) which columns are angles (degrees in the file).
        planner: the planner that found the approach.
        planning_time_s: the planning wall time (planner, simplification, checks, timing).
        found: whether a motion was found; else ``reason`` says why in one line.
    """

    joint_names: list[str]
    times: np.ndarray
    positions: np.ndarray
    revolute: np.ndarray
    planner: str = "RRTConnect"
    planning_time_s: float = 0.0
    found: bool = True
    reason: str = ""

    @classmethod
    def missing(cls, joint_names: list[str], revolute: np.ndarray, reason: str, planning_time_s: float,
                planner: str = "RRTConnect") -> Trajectory:
        """No motion: ``found`` false and the one-line reason."""
        n = len(joint_names)
        return cls(joint_names, np.zeros(0), np.zeros((0, n)), revolute, planner, planning_time_s, False, reason)

    def to_dict(self) -> dict:
        """The result file's ``trajectory`` (degrees for the angles)."""
        scale = np.where(self.revolute, 180.0 / math.pi, 1.0)
        return {"joint_names": list(self.joint_names), "times": [float(t) for t in self.times],
                "positions": (self.positions * scale).tolist(), "planner": self.planner,
                "planning_time_s": float(self.planning_time_s), "found": bool(self.found), "reason": self.reason}

    @classmethod
    def from_dict(cls, data: dict, revolute: np.ndarray) -> Trajectory:
        """The inverse of :meth:`to_dict` (``revolute``: which columns are angles)."""
        positions = np.asarray(data["positions"], dtype=np.float64).reshape(-1, len(data["joint_names"]))
        return cls(list(data["joint_names"]), np.asarray(data["times"], dtype=np.float64),
                   positions * np.where(revolute, math.pi / 180.0, 1.0), np.asarray(revolute, dtype=bool),
                   data.get("planner", ""), float(data.get("planning_time_s", 0.0)), bool(data["found"]),
                   data.get("reason", ""))


class TrialResult:
    """One trial: the configuration it found and how good it is.

    The common core: ``success`` (the grasp: every contact within ``solver.tolerance_mm`` and,
    where the problem has an object or obstacles, no collision by FCL), ``iterations``,
    ``reinforcement`` (the reward's value there, noise-free; the paper's threshold applies to it),
    ``wall_time_s``, ``collisions`` and ``error_mm`` (the error the trial is ranked by: E of eq. 3,
    or a gripper's d). Everything else is what the robot's environment reports
    (:meth:`~graspnet_torch.solver.environment.Environment.report`), read as attributes
    (``trial.fingertip_error_mm``; a field the robot does not report reads None) and written to
    the JSON (INTERFACE.md)."""

    def __init__(self, success: bool, iterations: int, reinforcement: float, wall_time_s: float, collisions: int = 0,
                 error_mm: float | None = None, **fields):
        self.success, self.iterations, self.reinforcement = success, iterations, reinforcement
        self.wall_time_s, self.collisions, self.fields = wall_time_s, collisions, fields
        self.error_mm = error_mm if error_mm is not None else fields.get("total_error_mm")

    def __getattr__(self, name: str):
        if name in FIELD_ORDER:  # a field of the JSON this robot does not report
            return self.__dict__.get("fields", {}).get(name)
        raise AttributeError(f"{type(self).__name__!r} has no attribute {name!r}")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TrialResult) and self.to_dict() == other.to_dict() and self.error_mm == other.error_mm

    def __repr__(self) -> str:
        return f"TrialResult({', '.join(f'{k}={v!r}' for k, v in self.to_dict().items())})"

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], error_keys: Sequence[str] = ERROR_KEYS) -> TrialResult:
        """The inverse of :meth:`to_dict`: a trial as read back from a result file. ``error_mm`` is
        the first of ``error_keys`` the trial has (None if none); a core field it lacks reads
        ``iterations`` 0, ``reinforcement`` None, ``wall_time_s`` 0.0, ``collisions`` 0."""
        fields = {k: v for k, v in data.items() if k not in _CORE}
        error = next((data[k] for k in error_keys if k in data), None)
        return cls(data.get("success", False), data.get("iterations", 0), data.get("reinforcement"),
                   data.get("wall_time_s", 0.0), data.get("collisions", 0), error, **fields)

    def to_dict(self) -> dict:
        core = {"success": self.success, "iterations": self.iterations, "reinforcement": self.reinforcement,
                "wall_time_s": self.wall_time_s, "collisions": self.collisions}  # the keys of _CORE
        every = {**core, **{k: v for k, v in self.fields.items() if v is not None}}
        return {k: every[k] for k in sorted(every, key=lambda k: (FIELD_ORDER.index(k) if k in FIELD_ORDER
                                                                  else len(FIELD_ORDER)))}


@dataclass
class GraspResult:
    """The best trial's fields at top level, plus every trial."""

    robot: str
    trials: list[TrialResult]
    problem: str | None = None
    seed: int | None = None
    settings: dict = field(default_factory=dict)

    outcome: object | None = field(default=None, repr=False, compare=False)  # the loop's tensors and curves
    failure: str | None = None  # why no trial succeeded (one line), or None
    chosen: int | None = None  # the reported trial's index, when a solver chose it (tracking: the nearest)
    trajectory: Trajectory | None = None  # the reach motion to the reported grasp (reach=true), or None

    @property
    def best(self) -> TrialResult:
        """The reported trial: the one the solver ``chosen`` (a tracked frame's successful trial
        nearest the previous frame), else the successful trial with the smallest total error,
        collision-free ones first (else the smallest error, collision-free first)."""
        if self.chosen is not None:
            return self.trials[self.chosen]
        return min(self.trials, key=lambda t: (not t.success, t.collisions > 0, t.error_mm))

    @property
    def success(self) -> bool:
        """The reported trial's ``success``: the grasp."""
        return self.best.success

    def __getattr__(self, name: str):
        """The reported trial's fields at the top level, as in the JSON (``result.palm_pose``,
        ``result.total_error_mm``, ``result.iterations``, ...: :class:`TrialResult`)."""
        if name.startswith("_") or name in _RESULT_ATTRIBUTES:  # not (yet) set: no trial to ask
            raise AttributeError(f"{type(self).__name__!r} has no attribute {name!r}")
        return getattr(self.best, name)

    def to_dict(self) -> dict:
        out = {"robot": self.robot, **self.best.to_dict(), "trials": [t.to_dict() for t in self.trials]}
        if self.failure is not None:
            out["failure"] = self.failure
        if self.problem is not None:
            out["problem"] = self.problem
        if self.seed is not None:
            out["seed"] = self.seed
        if self.settings:
            out["settings"] = self.settings
        if self.trajectory is not None:
            out["trajectory"] = self.trajectory.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], revolute: np.ndarray | None = None,
                  error_keys: Sequence[str] = ERROR_KEYS) -> GraspResult:
        """The inverse of :meth:`to_dict`: a result file read back (``from_dict(r.to_dict()).to_dict()
        == r.to_dict()``). The reported trial is the one whose fields are the top level's
        (``chosen``); a file without ``trials`` holds that one trial only. The ``trajectory`` is
        read when ``revolute`` ((n,) which of its joints are angles; the robot's) is given, else
        left out. Raises KeyError, TypeError or ValueError on what is not a result."""
        if not isinstance(data, Mapping):
            raise TypeError(f"a result is a mapping, not {type(data).__name__}")
        top = {k: v for k, v in data.items() if k not in _RESULT_KEYS}
        rows = data.get("trials")
        rows = [top] if rows is None else rows
        if not isinstance(rows, list) or not rows or not all(isinstance(t, Mapping) for t in rows):
            raise TypeError("a result's trials are a non-empty list of mappings")
        trials = [TrialResult.from_dict(t, error_keys) for t in rows]
        chosen = next((k for k, t in enumerate(rows) if dict(t) == top), None)
        trajectory = data.get("trajectory")
        motion = Trajectory.from_dict(trajectory, revolute) if trajectory is not None and revolute is not None \
            else None
        return cls(str(data["robot"]), trials, data.get("problem"), data.get("seed"), dict(data.get("settings") or {}),
                   failure=data.get("failure"), chosen=chosen, trajectory=motion)

    def to_json(self, indent: int | None = 2) -> str:
        """Strict JSON; a non-finite number anywhere is an :class:`InternalError` (NaN and
        infinity are not JSON, and no result with them is ever written)."""
        try:
            return json.dumps(self.to_dict(), indent=indent, allow_nan=False)
        except ValueError:
            raise InternalError(f"the result of {self.problem or 'the problem'} is not finite (NaN or infinity "
                                f"in {', '.join(_non_finite(self.to_dict())[:3])}); nothing was written") from None

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically (never a half-written file; never a non-finite one)."""
        return atomic_write_text(path, self.to_json() + "\n")


def _non_finite(obj, prefix: str = "") -> list[str]:
    """Dotted paths of the non-finite floats in a JSON-like object."""
    if isinstance(obj, float):
        return [] if math.isfinite(obj) else [prefix or "<root>"]
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _non_finite(v, f"{prefix}.{k}" if prefix else str(k))]
    if isinstance(obj, list | tuple):
        return [p for i, v in enumerate(obj) for p in _non_finite(v, f"{prefix}[{i}]")]
    return []
