"""A collision-free path in joint space between two states, with OMPL (RRT-Connect, then OMPL's
path simplification).

The planner works in scaled units (each variable divided by its check step, ``resolution_deg`` or
``resolution_mm``), so one unit moves every joint by at most its step; its motion validator
checks a straight motion state by state at that step (FCL, batched forward kinematics), so
what it accepts is exactly what :func:`~graspnet_torch.motion.check_motion` re-checks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

__all__ = ["SIMPLIFY_S", "plan_path"]

RANGE_SHARE = 0.1  # the planner's longest step: this share of the space's diagonal (0.2 before: MANUS grasps
# whose arm reaches over the table took 14 s, long steps failing near it; 13 of the 64 positions in 0.8 s, not 5)
SIMPLIFY_S = 0.5  # at most this long simplifying a path found (within the time left)


def plan_path(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray, scale: np.ndarray,
              segment_clear: Callable[[np.ndarray, np.ndarray], bool], state_clear: Callable[[np.ndarray], bool],
              timeout_s: float, seed: int = 0, reach: float | None = None) -> tuple[np.ndarray | None, str]:
    """A path from ``start`` to ``goal`` (n,) within [lower, upper].

    Args:
        scale: (n,) each variable's check step (the planner's unit).
        segment_clear: whether the straight motion between two states (internal units) is clear
            (both ends included).
        state_clear: whether one state is clear.
        timeout_s: the planner's budget.
        seed: OMPL's random seed.
        reach: the planner's longest step (scaled units; None: :data:`RANGE_SHARE` of the space's diagonal).
    Returns:
        the waypoints (W, n) from start to goal (internal units), or None and a one-line reason.
    """
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) + 1)  # OMPL refuses seed 0
    if segment_clear(start, goal):
        return np.stack([start, goal]), ""
    n = start.shape[0]
    lo, hi = lower / scale, upper / scale
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for k in range(n):
        bounds.setLow(k, float(lo[k]))
        bounds.setHigh(k, float(hi[k]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)

    def unscaled(state) -> np.ndarray:
        return np.array([state[k] for k in range(n)]) * scale

    setup.setStateValidityChecker(lambda s: bool(state_clear(unscaled(s))))
    info = setup.getSpaceInformation()

    class Segments(ob.MotionValidator):
        def checkMotion(self, s1, s2, *last) -> bool:  # OMPL's name
            return bool(segment_clear(unscaled(s1), unscaled(s2)))

    validator = Segments(info)
    info.setMotionValidator(validator)
    begin, end = space.allocState(), space.allocState()
    for k in range(n):
        begin[k], end[k] = float(start[k] / scale[k]), float(goal[k] / scale[k])
    setup.setStartAndGoalStates(begin, end)
    planner = og.RRTConnect(info)
    planner.setRange(max(1.0, reach if reach is not None else RANGE_SHARE * math.sqrt(float(np.sum((hi - lo) ** 2)))))
    setup.setPlanner(planner)
    t0 = time.perf_counter()
    status = setup.solve(float(timeout_s))
    if not setup.haveExactSolutionPath():
        setup.clear()
        return None, f"OMPL found no collision-free path in the {timeout_s:.2g} s left ({status})"
    left = min(max(0.05, timeout_s - (time.perf_counter() - t0)), SIMPLIFY_S)
    setup.getPathSimplifier().simplify(setup.getSolutionPath(), left)
    path = setup.getSolutionPath()
    out = np.stack([unscaled(path.getState(i)) for i in range(path.getStateCount())])
    setup.clear()
    out[0], out[-1] = start, goal  # exact ends (the planner's copies went through the scaling)
    return out, ""


ASIDE_TRIES = 20  # waypoints tried beside a grazing straight motion
ASIDE_STEPS = 2.0  # ... drawn this many check steps (times the try's number) from its middle


def step_aside(u: np.ndarray, v: np.ndarray, moving: np.ndarray, step: np.ndarray, lower: np.ndarray,
               upper: np.ndarray, segment_clear: Callable[[np.ndarray, np.ndarray], bool], seed: int = 0
               ) -> np.ndarray | None:
    """A waypoint w beside the middle of the straight motion u -> v (n,), moving only the
    variables ``moving``, such that u -> w and w -> v are clear (``segment_clear``): a motion
    that grazes something (clear at one sampling of its line, not at another) goes around it.
    Drawn from one generator seeded by ``seed`` at ``ASIDE_STEPS`` times the try's number of check
    steps (``step`` (n,)) from the middle, within [lower, upper]; None after ``ASIDE_TRIES``."""
    rng = np.random.default_rng(seed)
    for k in range(ASIDE_TRIES):
        w = (u + v) / 2
        w[moving] += rng.normal(size=len(moving)) * step[moving] * ASIDE_STEPS * (1 + k)
        w = np.minimum(np.maximum(w, lower), upper)
        if segment_clear(u, w) and segment_clear(w, v):
            return w
    return None
