"""The planner's way around a straight motion that grazes something (motion.planner.step_aside)."""

from __future__ import annotations

import numpy as np

from graspnet_torch.motion.planner import step_aside


def _clear_of_disc(radius: float):
    """A segment is clear when it passes no nearer than ``radius`` to the origin (2-D)."""

    def clear(a: np.ndarray, b: np.ndarray) -> bool:
        d = b - a
        t = np.clip(-a @ d / max(d @ d, 1e-12), 0.0, 1.0)
        return bool(np.linalg.norm(a + t * d) >= radius)

    return clear


def test_a_grazing_motion_goes_around_through_a_waypoint_beside_its_middle():
    u, v = np.array([-1.0, 0.0]), np.array([1.0, 0.0])
    clear = _clear_of_disc(0.05)
    assert not clear(u, v)
    step, lo, hi = np.full(2, 0.02), np.full(2, -2.0), np.full(2, 2.0)
    w = step_aside(u, v, np.arange(2), step, lo, hi, clear, seed=0)
    assert w is not None and clear(u, w) and clear(w, v)
    again = step_aside(u, v, np.arange(2), step, lo, hi, clear, seed=0)
    np.testing.assert_array_equal(w, again)  # the same seed, the same waypoint


def test_no_waypoint_where_only_the_blocked_variable_may_move():
    """Moving only x (the motion's own direction), every waypoint lies on the blocked line: None."""
    u, v = np.array([-1.0, 0.0]), np.array([1.0, 0.0])
    step, lo, hi = np.full(2, 0.02), np.full(2, -2.0), np.full(2, 2.0)
    assert step_aside(u, v, np.array([0]), step, lo, hi, _clear_of_disc(0.05), seed=0) is None
