"""A timed motion in joint space and its time parameterisation.

A path is a polyline in joint space (waypoints (W, n), internal units: rad, m). Each of its
segments is timed on its own from rest to rest with Ruckig, phase-synchronised (every joint
starts and stops together, so the motion stays on the straight segment the collision check
tested), within each joint's velocity and the acceleration limit; the timed motion is sampled
at ``sample_hz`` and at every corner (:class:`Trajectory`).
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np

from graspnet_torch.solver.result import Trajectory  # the result's trajectory, defined with the result

__all__ = ["TooManyRows", "Trajectory", "time_path"]


class TooManyRows(ValueError):
    """A timed motion that would have more rows than allowed (``reach.max_samples``): its
    ``rows`` and ``duration`` (s), found before any row is made."""

    def __init__(self, rows: int, duration: float):
        super().__init__(f"{rows} rows over {duration:.4g} s")
        self.rows, self.duration = rows, duration


def time_path(waypoints: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, sample_hz: float,
              max_rows: int = 10_000_000) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Time a polyline from rest to rest, segment by segment (Ruckig, phase-synchronised).

    Args:
        waypoints: (W, n) corners, internal units.
        velocity, acceleration: (n,) limits per joint.
        sample_hz: samples per second within a segment.
        max_rows: the most rows the motion may have; more raise :class:`TooManyRows` before any
            row is made (a slow acceleration at a high rate is hours of rows).
    Returns:
        times (S,), positions (S, n) and the row of each corner (W,).
    """
    from ruckig import InputParameter, Result, Ruckig, Synchronization
    from ruckig import Trajectory as RuckigTrajectory

    W, n = waypoints.shape
    otg = Ruckig(n)
    segments = []  # (a, b, trajectory, steps) of each segment that moves
    for a, b in pairwise(waypoints):
        if np.max(np.abs(b - a)) < 1e-12:
            continue
        inp = InputParameter(n)
        inp.current_position, inp.target_position = a.tolist(), b.tolist()
        inp.current_velocity = inp.current_acceleration = [0.0] * n
        inp.target_velocity = inp.target_acceleration = [0.0] * n
        inp.max_velocity, inp.max_acceleration = velocity.tolist(), acceleration.tolist()
        inp.max_jerk = [math.inf] * n
        inp.synchronization = Synchronization.Phase
        traj = RuckigTrajectory(n)
        if otg.calculate(inp, traj) not in (Result.Working, Result.Finished):
            raise RuntimeError("ruckig could not time a segment")
        segments.append((a, b, traj, max(1, math.ceil(traj.duration * sample_hz))))
    total = 1 + sum(seg[3] for seg in segments)
    if total > max_rows:
        raise TooManyRows(total, sum(seg[2].duration for seg in segments))
    times, rows, corners = [0.0], [waypoints[0].copy()], [0]
    for a, b, traj, steps in segments:
        t0, duration = times[-1], traj.duration
        for k in range(1, steps + 1):
            t = duration * k / steps
            p = b if k == steps else _on_segment(a, b, np.asarray(traj.at_time(t)[0]))
            times.append(t0 + t)
            rows.append(np.asarray(p, dtype=np.float64))
        corners.append(len(rows) - 1)
    while len(corners) < W:  # repeated corners (no motion between them)
        corners.append(len(rows) - 1)
    return np.asarray(times), np.stack(rows), corners


def _on_segment(a: np.ndarray, b: np.ndarray, p: np.ndarray) -> np.ndarray:
    """p projected onto the segment a-b (phase synchronisation keeps it there up to rounding)."""
    d = b - a
    s = float(np.clip((p - a) @ d / (d @ d), 0.0, 1.0))
    return a + s * d
