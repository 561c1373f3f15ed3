"""Reach motions (beyond the paper: its section 8's future work): from a start configuration to
the reported grasp, collision-free, timed.

A robot with a body (an arm carrying a hand, the MANUS) moves in three straight or planned parts:

1. at the start, its fingers open (to the pre-grasp opening, below);
2. OMPL plans the body's joints to the grasp's, fingers open, every link clear of the object,
   the obstacles, the floor and its own links (the strict scene: no fingertip may touch);
3. at the grasp, the fingers close on their contacts (where, as in the result, the contact
   fingertips may touch the object).

The opening (:mod:`~graspnet_torch.motion.openings`): fingers at the grasp with no link touching the
object, from which the fingers close onto the grasp clear: each contact fingertip backed off its contact by up to
4 cm, away from the object's centre or curling toward the palm (finger inverse kinematics), or
the fingers straightened toward their home; each finger at its own most open clear one first. A
gripper (the MANUS) has no fingers: its jaws may touch the object as in the result. A free hand
has no start: its motion is the approach from a pre-grasp pose, the palm backed off
``reach.backoff_m`` from the grasp away from the contacts with the fingers open, in a straight
line to the grasp, then the fingers close.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspnet_torch.collision.scene import CollisionScene, has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.least_squares import LMOptions, frame_model, levenberg_marquardt
from graspnet_torch.motion.config import ReachCfg
from graspnet_torch.motion.openings import OPENINGS_M, opening, openings
from graspnet_torch.motion.planner import plan_path, step_aside
from graspnet_torch.motion.trajectory import TooManyRows, Trajectory, time_path
from graspnet_torch.motion.validity import MotionChecker, StateLayout
from graspnet_torch.robot.heads import head_of
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.transforms import pose_to_rt, rt_to_pose
from graspnet_torch.solver.api import robot_of
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.tasks.problem import GraspProblem

if TYPE_CHECKING:
    from graspnet_torch.solver.result import GraspResult, TrialResult

__all__ = ["OPENINGS_M", "check_motion", "check_start", "colliding_row", "plan_reach", "start_posture"]

PLANNER = "RRTConnect"
DETOUR_DEG, DETOUR_M = 15.0, 0.05  # a detour searches this far around the stretch it replaces
COARSE = 3  # the planner checks its motions at 3x the check step; the motion found is then checked at it
# (6x before: MANUS motions whose coarse path grazed the table spent 13 s in local detours at the step)
BACK_OFF_STEPS, BACK_OFF_DAMPING = 40, 1e-2  # the back-off's least squares: most steps, its fixed damping (m)
BACK_OFF_TOL_M, BACK_OFF_TOL_DEG = 1e-3, 0.5  # a back-off counts when its palm lies this near its target
DETOUR_FINER = 8  # a detour whose motions are not clear at the check step is planned again at 1/8 of it
DRIVE_SHARE = 0.3  # a mobile base's drive, planned where the straight one collides, gets this share of the time
ARM_SHARE = 0.6  # the arm's plan after the drive this share of what is left (base and arm together the rest)


def start_posture(robot: Robot, problem: GraspProblem) -> Posture:
    """The configuration a reach motion starts from: the problem's ``start`` (by URDF joint name,
    degrees or metres as written; joints left out at home), else the home posture. Refuses
    (:class:`ProblemError`) an unknown joint or a value outside its limits."""
    home = robot.home_posture(torch.float64)
    if not problem.start:
        return home
    where = f"{problem.source}: start"
    if not head_of(robot).anchored:
        raise ProblemError(f"{where}: robot '{robot.name}' has no body (a free hand's motion is its approach)")
    body, fingers = home.body.clone(), home.fingers.clone()
    finger_slots = {name: (k, i) for k, f in enumerate(robot.fingers.values())
                    for i, name in enumerate(f.chain.joint_names)}
    kinds = dict(zip(robot.body_joint_names, robot.body.joint_types, strict=True))
    for name, value in problem.start.items():
        if name in kinds:
            k = robot.body_joint_names.index(name)
            revolute = kinds[name] != "prismatic"
            v = math.radians(value) if revolute else value
            lo, hi = robot.body_limits[0][k], robot.body_limits[1][k]
            body[k] = v
        elif name in finger_slots:
            k, i = finger_slots[name]
            finger = robot.fingers[robot.finger_names[k]]
            revolute = finger.chain.spec.joint_types[finger.chain.free[i]] != "prismatic"
            v = math.radians(value) if revolute else value
            lo, hi = robot.finger_limits[0][k, i], robot.finger_limits[1][k, i]
            fingers[k, i] = v
        else:
            known = list(robot.body_joint_names) + list(finger_slots)
            raise ProblemError(f"{where}: unknown joint '{name}' of robot '{robot.name}' (joints: "
                               f"{', '.join(known[:12])}{', ...' if len(known) > 12 else ''})")
        if not lo - 1e-9 <= v <= hi + 1e-9:
            unit, scale = ("deg", 180 / math.pi) if revolute else ("m", 1.0)
            raise ProblemError(f"{where}.{name}: {value:g} lies outside its limits [{lo * scale:.4g}, "
                               f"{hi * scale:.4g}] {unit}")

    return Posture(palm_pose=rt_to_pose(*robot.palm_frame(body)), fingers=fingers, body=body)


def check_start(robot: Robot, problem: GraspProblem) -> None:
    """Refuse (:class:`ProblemError`, before any work) a reach start with an unknown joint, outside
    its limits, or colliding (FCL, with the fingers as given)."""
    _refuse_shared(robot, problem)
    posture = start_posture(robot, problem)
    if not head_of(robot).anchored:  # a free palm starts at its approach, not at a configuration
        return

    if has_environment(robot, problem):
        report = CollisionScene(robot, problem, touching=False).check(posture)
        if report.count:
            what = [f"{link} with obstacle {o}" for link, o in report.obstacle_pairs][:2] + \
                [f"{link} in the object" for link in report.object_links][:2] + \
                [f"{a} with {b}" for a, b in report.self_pairs][:2]
            named = "the problem's start" if problem.start else "the home posture (the default start)"
            raise ProblemError(f"{problem.source}: start: {named} collides ({', '.join(what)})")


def _refuse_shared(robot: Robot, problem: GraspProblem) -> None:
    if robot.shared.names:
        raise ProblemError(f"{problem.source}: reach: robot '{robot.name}' has joints its fingers share "
                           f"({', '.join(robot.shared.names)}); reach motions do not move them yet")


def plan_reach(problem: GraspProblem, result: GraspResult | TrialResult, cfg: ReachCfg | None = None,
               robot: Robot | None = None) -> Trajectory:
    """The reach motion to a result's grasp (its best trial, or the trial given): collision-free
    (FCL at ``reach.resolution_deg`` / ``resolution_mm`` between consecutive rows) and timed
    within the URDF's velocity limits and ``reach.acceleration``. A motion not found within
    ``reach.timeout_s`` comes back with ``found`` false and a one-line reason."""
    cfg = cfg or ReachCfg()
    robot = robot or robot_of(problem.robot_cfg or problem.robot)
    _refuse_shared(robot, problem)
    trial = result.best if hasattr(result, "best") else result  # a GraspResult or one of its trials
    t0 = time.perf_counter()
    layout = StateLayout.of(robot, cfg.palm_speed)
    checker = MotionChecker(robot, problem, layout, cfg.touch_mm)
    goal = checker.state(trial_posture(robot, trial))
    pregrasp = None if trial.pregrasp is None else checker.state(trial_posture(robot, trial.pregrasp))
    velocity = layout.velocity
    acceleration = np.full_like(velocity, cfg.acceleration)
    res = (cfg.resolution_deg, cfg.resolution_mm)
    fine = (res[0] / DETOUR_FINER, res[1] / DETOUR_FINER)  # a grazing motion's way around is checked at this
    deadline = t0 + cfg.timeout_s
    if head_of(robot).anchored:
        corners, reason = _body_path(robot, problem, checker, goal, cfg, deadline, pregrasp)
    else:
        corners, reason = _hand_path(robot, problem, checker, goal, cfg, pregrasp)
    while corners is not None:  # the rows are checked as check_motion does; a colliding stretch is planned again
        try:
            times, rows, at = time_path(corners, velocity, acceleration, cfg.sample_hz, cfg.max_samples)
        except TooManyRows as exc:
            return Trajectory.missing(
                list(layout.names), layout.revolute,
                f"the timed motion lasts {exc.duration:.4g} s: {exc.rows} rows at reach.sample_hz={cfg.sample_hz:g}, "
                f"more than reach.max_samples={cfg.max_samples} (raise reach.acceleration or reach.max_samples, or "
                f"lower reach.sample_hz)", time.perf_counter() - t0, PLANNER)
        k = colliding_row(checker, rows, *res)
        if k is None:
            return Trajectory(list(layout.names), times, rows, layout.revolute, PLANNER, time.perf_counter() - t0)
        j = int(np.searchsorted(at, k, side="right")) - 1  # the corner segment the colliding rows lie on
        # (the detour moves the joints that segment moves)
        u, v = corners[j], corners[j + 1]
        moving = np.nonzero(np.abs(v - u) > 1e-12)[0]
        if not head_of(robot).anchored or np.any(moving >= layout.body):  # a straight part (fingers, approach)
            reason = "a straight part of the motion collides between its rows at the check step"
            break
        for divide in (1, DETOUR_FINER):  # the detour's motions checked at the step (finer where that is not enough)
            detour, reason = _plan(checker, u, v, moving, cfg, (res[0] / divide, res[1] / divide), deadline,
                                   local=True)
            if detour is None or len(detour) > 2:
                break
        if detour is None:
            break
        if len(detour) == 2:  # clear at an eighth of the step but not at the step: a grazing contact; around it
            w = step_aside(u, v, moving, layout.scale(*res), layout.lower, layout.upper,
                           lambda a, b: checker.first_collision(a, b, *fine) is None, cfg.seed)
            if w is None:
                reason = "the motion grazes an obstacle between its rows at the check step"
                break
            detour = [u, w, v]
        corners = np.concatenate([corners[: j + 1], np.stack(detour[1:-1]), corners[j + 1:]])
    reason = reason or "no collision-free path"
    return Trajectory.missing(list(layout.names), layout.revolute, f"{reason} (reach.timeout_s={cfg.timeout_s:g} s)",
                              time.perf_counter() - t0, PLANNER)


def colliding_row(checker: MotionChecker, rows: np.ndarray, resolution_deg: float, resolution_mm: float,
                  batch: int = 64) -> int | None:
    """The first row k whose straight line to row k + 1, tested at the step (both ends included),
    collides; None: none does. Each row is tested once (the end of one line is the start of the
    next)."""
    states, owner = [rows[:1]], [0]
    for k in range(len(rows) - 1):
        n = checker.layout.steps(rows[k], rows[k + 1], resolution_deg, resolution_mm)
        s = np.arange(1, n + 1)[:, None] / n
        states.append(rows[k] + s * (rows[k + 1] - rows[k]))
        owner += [k] * n
    every, owner = np.concatenate(states), np.asarray(owner)
    for start in range(0, len(every), batch):
        ok = checker.clear(every[start: start + batch])
        if not ok.all():
            return int(owner[start + int(np.argmin(ok))])
    return None


def _body_path(robot: Robot, problem: GraspProblem, checker: MotionChecker, goal: np.ndarray, cfg: ReachCfg,
               deadline: float, pregrasp: np.ndarray | None = None) -> tuple[np.ndarray | None, str]:
    """Corners: start, start with the fingers open, (planned), the grasp's body with the fingers open
    (the result's pre-grasp where it has one and it is clear), the grasp; or None and why. A mobile
    base first drives (a straight line, the arm as at the start; where that collides, the base's
    motion planned alone), then the arm is planned with the base where the grasp has it; where
    that fails, base and arm are planned together (by :func:`_plan`, until ``deadline``)."""
    m = checker.layout.body
    start = checker.state(start_posture(robot, problem))
    pre = opening(checker, problem, goal, cfg, pregrasp)
    if pre is None:
        return None, "no pre-grasp opening of the fingers at the grasp is clear of the object"
    opened = start.copy()
    opened[m:] = pre[m:]
    res = (cfg.resolution_deg, cfg.resolution_mm)
    if problem.fingers and checker.first_collision(start, opened, *res) is not None:
        return None, "opening the fingers at the start collides"

    coarse = (cfg.resolution_deg * COARSE, cfg.resolution_mm * COARSE)  # the planner's step (then checked finer)
    final: list[np.ndarray] = []  # the straight approach from a backed-off pre-grasp, when there is one
    backed = _backed_off(robot, problem, checker, pre, cfg.approach_m)
    if backed is not None and checker.strictly_clear(backed[None])[0] and \
            checker.first_collision(backed, pre, *res) is None:
        pre, final = backed, [pre]
    path, reason = None, ""
    base = len(robot.urdf.chain_spec(robot.cfg.mobile_base.base, robot.cfg.mobile_base.tip).joint_names) \
        if robot.cfg.mobile_base is not None else 0
    if base:  # drive (straight, else planned for the base alone), then reach
        driven = opened.copy()
        driven[:base] = pre[:base]
        drive: list[np.ndarray] | None = [opened, driven]
        if checker.first_collision(opened, driven, *res) is not None:
            drive, reason = _plan(checker, opened, driven, range(base), cfg, coarse, _share(deadline, DRIVE_SHARE))
        if drive is not None:
            arm, reason = _plan(checker, driven, pre, range(base, m), cfg, coarse, _share(deadline, ARM_SHARE))
            if arm is not None:
                path = [*drive, *arm[1:]]
    if path is None:
        path, reason = _plan(checker, opened, pre, range(m), cfg, coarse, deadline)
    if path is None:
        return None, reason or "no collision-free path"
    corners = [start, *path, *final] + ([goal] if problem.fingers else [])  # a gripper's pre-grasp is its goal
    return _distinct(np.stack(corners)), ""


def _share(deadline: float, share: float) -> float:
    """A deadline ``share`` of the way from now to ``deadline``."""
    now = time.perf_counter()
    return now + share * max(0.0, deadline - now)


def _backed_off(robot: Robot, problem: GraspProblem, checker: MotionChecker, state: np.ndarray, distance: float
                ) -> np.ndarray | None:
    """The state with the palm (a gripper's frame) moved ``distance`` away from the contacts
    (their centroid; a gripper: its object points' midpoint), its orientation kept: damped least
    squares on the body joints (the palm frame as a residual on the one Levenberg-Marquardt, at a
    fixed damping, clamped to the limits); None when that is not reached within
    :data:`BACK_OFF_TOL_M` / :data:`BACK_OFF_TOL_DEG`."""
    m = checker.layout.body
    q = torch.as_tensor(state[:m].copy())
    R0, t0 = robot.palm_frame(q)
    targets = np.asarray(problem.contacts_world() if problem.fingers else problem.points_world(), dtype=np.float64)
    away = t0.numpy() - targets.mean(0)
    if np.linalg.norm(away) < 1e-9:
        return None
    goal_t = t0 + torch.as_tensor(distance * away / np.linalg.norm(away))
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    goal = torch.cat([goal_t, torch.zeros(3, dtype=torch.float64)])
    d = BACK_OFF_DAMPING
    fixed = LMOptions(lam=d, lam_min=d, lam_max=d, active_set=False, tol=1e-4)
    frame = frame_model(robot.palm_frame_jacobian, R0)  # the palm frame: position, then its turn back to R0
    q = levenberg_marquardt(frame, goal, q[None], lo, hi, BACK_OFF_STEPS, fixed).x[0]
    R, t = robot.palm_frame(q)
    E = R0 @ R.T
    turn = float(torch.arccos(((E.trace() - 1) / 2).clamp(-1, 1)))
    if float((goal_t - t).norm()) > BACK_OFF_TOL_M or turn > math.radians(BACK_OFF_TOL_DEG):
        return None
    out = state.copy()
    out[:m] = q.numpy()
    return out


def _plan(checker: MotionChecker, a: np.ndarray, b: np.ndarray, dims: range | np.ndarray, cfg: ReachCfg,
          step: tuple[float, float], deadline: float, local: bool = False) -> tuple[list[np.ndarray] | None, str]:
    """Full states from a to b (included) moving only the variables ``dims``, planned with motions
    checked at ``step`` (the caller checks the result at its own step, and plans a colliding
    stretch again, finer). ``local``: a detour, searched within :data:`DETOUR_DEG` (prismatic:
    :data:`DETOUR_M`) of the box spanned by a and b, with steps of at most half their distance."""
    dims = np.asarray(dims)
    lower, upper = checker.layout.lower[dims], checker.layout.upper[dims]
    reach = None
    if local:
        margin = np.where(checker.layout.revolute[dims], math.radians(DETOUR_DEG), DETOUR_M)
        lower = np.maximum(lower, np.minimum(a[dims], b[dims]) - margin)
        upper = np.minimum(upper, np.maximum(a[dims], b[dims]) + margin)
        reach = 0.5 * float(np.linalg.norm((b[dims] - a[dims]) / checker.layout.scale(*step)[dims]))
    coarse = step

    def full(x: np.ndarray) -> np.ndarray:
        out = a.copy()
        out[dims] = x
        return out

    left = deadline - time.perf_counter()
    if left <= 0:
        return None, "no time left"
    path, reason = plan_path(a[dims], b[dims], lower, upper, checker.layout.scale(*coarse)[dims],
                             lambda x, y: checker.first_collision(full(x), full(y), *coarse) is None,
                             lambda x: bool(checker.clear(full(x)[None])[0]), left, cfg.seed, reach)
    if path is None:
        return None, reason
    return [full(x) for x in path], ""


def _hand_path(robot: Robot, problem: GraspProblem, checker: MotionChecker, goal: np.ndarray, cfg: ReachCfg,
               pregrasp: np.ndarray | None = None) -> tuple[np.ndarray | None, str]:
    """A free hand's approach: the pre-grasp pose (the palm backed off ``reach.backoff_m``, its
    orientation kept, the fingers open), in a straight line to the grasp's palm, then the
    fingers close. The directions tried, in order: away from the contacts' centroid, away from
    the object's centre, then along each of the palm frame's axes both ways."""
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64)
    palm = goal[:3]
    R, _t = pose_to_rt(torch.as_tensor(goal[:6]))
    candidates = [palm - contacts.mean(0)]
    if problem.object is not None:
        candidates.append(palm - np.asarray(problem.object.pose[:3], dtype=np.float64))
    candidates += [sign * R.numpy()[:, k] for k in range(3) for sign in (-1.0, 1.0)]
    directions: list[np.ndarray] = []
    for d in candidates:
        if np.linalg.norm(d) > 1e-9 and all(np.dot(d / np.linalg.norm(d), e) < 0.999 for e in directions):
            directions.append(d / np.linalg.norm(d))
    res = (cfg.resolution_deg, cfg.resolution_mm)
    reason = "no pre-grasp opening of the fingers at the grasp is clear of the object"
    for pre in openings(checker, problem, goal, cfg, pregrasp):
        for direction in directions:
            back = pre.copy()
            back[:3] = palm + cfg.backoff_m * direction
            if checker.first_collision(back, pre, *res) is None:
                return np.stack([back, pre, goal]), ""
        reason = (f"no straight approach from {cfg.backoff_m:g} m away ({len(directions)} directions tried) is clear "
                  f"at any opening of the fingers")
    return None, reason


def _distinct(corners: np.ndarray) -> np.ndarray:
    """Corners without consecutive repeats."""
    keep = [0] + [k for k in range(1, len(corners)) if np.max(np.abs(corners[k] - corners[k - 1])) > 1e-12]
    return corners[keep]


def check_motion(robot: Robot, problem: GraspProblem, trial: TrialResult, trajectory: Trajectory,
                 cfg: ReachCfg | None = None, resolution_deg: float = 0.5, resolution_mm: float = 1.0
                 ) -> list[str]:
    """An independent re-check of a motion; returns what fails (empty: it holds).

    - the first row is the start (a free hand: any pre-grasp) and the last the reported
      configuration (1e-6);
    - every row within the joint limits;
    - the velocities (finite differences) within the URDF's, the accelerations within
      ``reach.acceleration`` (1e-6 relative);
    - FCL at ``resolution_deg`` / ``resolution_mm`` along the straight lines between consecutive
      rows: clear (:class:`~graspnet_torch.motion.MotionChecker`: the contact fingertips may
      touch the object only within ``reach.touch_mm`` of their contacts).
    """
    cfg = cfg or ReachCfg()
    layout = StateLayout.of(robot, cfg.palm_speed)
    checker = MotionChecker(robot, problem, layout, cfg.touch_mm)
    x, t = trajectory.positions, trajectory.times
    out = []
    goal = checker.state(trial_posture(robot, trial))
    if np.max(np.abs(x[-1] - goal)) > 1e-6:
        out.append(f"the last row differs from the reported configuration by {np.max(np.abs(x[-1] - goal)):.3g}")
    if head_of(robot).anchored:
        start = checker.state(start_posture(robot, problem))
        if np.max(np.abs(x[0] - start)) > 1e-6:
            out.append(f"the first row differs from the start by {np.max(np.abs(x[0] - start)):.3g}")
    if np.any(x < layout.lower - 1e-9) or np.any(x > layout.upper + 1e-9):
        out.append("a row lies outside the joint limits")
    if np.any(np.diff(t) <= 0):
        out.append("the times do not increase")
    else:
        dt = np.diff(t)[:, None]
        v = np.diff(x, axis=0) / dt
        if np.any(np.abs(v) > layout.velocity * (1 + 1e-6)):
            out.append(f"a velocity exceeds its limit (by {np.max(np.abs(v) / layout.velocity):.4g}x)")
        if len(t) > 2:
            a = 2 * (v[1:] - v[:-1]) / (dt[1:] + dt[:-1])
            if np.any(np.abs(a) > cfg.acceleration * (1 + 1e-6)):
                out.append(f"an acceleration exceeds {cfg.acceleration:g} (up to {np.max(np.abs(a)):.4g})")
    hit = colliding_row(checker, x, resolution_deg, resolution_mm)
    if hit is not None:
        out.append(f"FCL finds a collision between rows {hit} and {hit + 1}")
    return out
