"""Grasp results and their JSON form (shared/INTERFACE.md).

Angles in degrees, lengths in metres, errors in millimetres. The reported errors are recomputed
in float64 from the reported configuration by forward kinematics against the problem's contacts,
so a result can be checked from the URDF alone.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

from graspnet_torch.errors import InternalError
from graspnet_torch.io import atomic_write_text

__all__ = ["GraspResult", "TrialResult"]


@dataclass
class TrialResult:
    """One trial: the configuration it found and how good it is. ``success`` means the grasp: every
    contact finger within ``solver.tolerance_mm`` of its contact (a gripper: d within it, aligned)
    and, where the problem has an object or obstacles, no collision (FCL); ``reinforcement`` is
    the reward's value there (the paper's threshold applies to it). Hand and arm_hand results have
    the finger fields; a gripper (MANUS) result has ``distance_mm``, ``alignment`` and
    ``gripper_points`` instead (INTERFACE.md); fields that do not apply are left out of the JSON."""

    success: bool
    iterations: int
    reinforcement: float  # noise-free, at the reported configuration
    wall_time_s: float
    palm_pose: list[float] | None = None  # palm_link in the world: x, y, z (m), rx, ry, rz (deg)
    joints: dict[str, list[float]] | None = None  # every finger, joints in chain order (deg)
    fingertip_error_mm: dict[str, float] | None = None  # contact fingers
    total_error_mm: float | None = None  # eq. 3
    collisions: int = 0
    arm_joints: dict[str, float] | None = None  # robots with a body: by URDF joint name, chain order (deg; m)
    distance_mm: float | None = None  # a gripper: d of eq. 26
    alignment: float | None = None  # a gripper: |n_gripper . n_object| (eq. 24)
    gripper_points: list[list[float]] | None = None  # a gripper: its two marked points in the world (m)

    @property
    def error_mm(self) -> float:
        """The error the trial is ranked by: E (eq. 3) for fingers, d (eq. 26) for a gripper."""
        return self.total_error_mm if self.total_error_mm is not None else self.distance_mm

    def to_dict(self) -> dict:
        return {k: v for k, v in asdict(self).items() if v is not None}


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

    @property
    def best(self) -> TrialResult:
        """The successful trial with the smallest total error, collision-free ones first (else the
        smallest error, collision-free first)."""
        return min(self.trials, key=lambda t: (not t.success, t.collisions > 0, t.error_mm))

    @property
    def success(self) -> bool:
        return self.best.success

    @property
    def palm_pose(self) -> list[float]:
        return self.best.palm_pose

    @property
    def joints(self) -> dict[str, list[float]]:
        return self.best.joints

    @property
    def fingertip_error_mm(self) -> dict[str, float]:
        return self.best.fingertip_error_mm

    @property
    def total_error_mm(self) -> float:
        return self.best.total_error_mm

    @property
    def iterations(self) -> int:
        return self.best.iterations

    @property
    def reinforcement(self) -> float:
        return self.best.reinforcement

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
        return out

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
