"""Settings of a reach motion (``reach`` on ``solve_grasp.py``; :func:`~graspnet_torch.motion.plan_reach`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from graspnet_torch.settings import build, setting

__all__ = ["ReachCfg"]


@dataclass(frozen=True)
class ReachCfg:
    """How a reach motion is planned, checked and timed (``reach=true``, or ``reach.KEY=...``).

    Attributes:
        enabled: plan the motion after the solve (``reach=true``).
        timeout_s: the planner's time for the approach (OMPL RRT-Connect, then its path
            simplification); past it the grasp is still reported, the motion is not.
        resolution_deg: the largest step of a revolute joint (and of the palm's angles) between two
            states the collision check tests along a motion.
        resolution_mm: the same for a prismatic joint (and the palm's position), millimetres.
        acceleration: the largest joint acceleration of the timed motion (rad/s^2; m/s^2 for a
            prismatic joint); the velocities are the URDF's ``<limit velocity>``.
        palm_speed: a free hand's palm: the largest speed (m/s; its angles rad/s), which a URDF
            does not give.
        touch_mm: a contact finger's distal link may touch the object only while its fingertip
            is within this of its contact (the finger closing on it, at the end of the motion; about
            the length of a distal link: the shipped hand's are about 25 mm); a gripper's jaws once both
            marked points are.
        backoff_m: a free hand's pre-grasp: the palm backed off this far from the grasp, away from
            the contacts.
        approach_m: a robot with a body: the pre-grasp its planned motion ends at, the palm (a
            gripper's frame) backed off this far from the grasp, away from the contacts, its
            orientation kept; from there a straight line to the grasp (where that pre-grasp is out of
            reach or collides, the motion is planned to the grasp itself).
        sample_hz: rows of the timed motion per second (and every corner of the path).
        max_samples: the most rows a timed motion may have (a slow ``acceleration`` at a high
            ``sample_hz`` is hours of rows: the result's size and the check's memory grow with
            them); a longer motion is not reported (``found`` false, the reason names this).
        seed: the planner's random seed.
    """

    enabled: bool = False
    timeout_s: float = setting(5.0, lo=0.0, lo_open=True, hi=3600.0)
    resolution_deg: float = setting(0.5, lo=0.01, hi=10.0)
    resolution_mm: float = setting(1.0, lo=0.01, hi=100.0)
    acceleration: float = setting(4.0, lo=0.0, lo_open=True, hi=1000.0)
    palm_speed: float = setting(0.5, lo=0.0, lo_open=True, hi=100.0)
    touch_mm: float = setting(40.0, lo=0.0, hi=1000.0)
    backoff_m: float = setting(0.1, lo=0.0, lo_open=True, hi=2.0)
    approach_m: float = setting(0.05, lo=0.0, lo_open=True, hi=1.0)
    sample_hz: float = setting(50.0, lo=1.0, hi=10_000.0)
    max_samples: int = setting(100_000, lo=2, hi=200_000)  # at most: 196k rows of the arm + hand peaked at 1.3 GB
    seed: int = setting(0, lo=0, hi=2**31 - 1)

    @classmethod
    def from_setting(cls, value: Any, where: str = "reach") -> ReachCfg:
        """``reach=true|false`` (the defaults, on or off) or a mapping of the keys above."""
        if isinstance(value, bool):
            return cls(enabled=value)
        if value is None:
            return cls()
        return build(cls, dict(value) if isinstance(value, Mapping) else value, where)
