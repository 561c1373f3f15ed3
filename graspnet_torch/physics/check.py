"""The physics check of a grasp in MuJoCo: :func:`simulate_grasp` -> :class:`PhysicsReport`.

The protocol is DexGraspBench's: friction 0.6 tangential / 0.02 torsional, elliptic cones, object
100 g, timestep 4 ms, an external force of the object's weight along +-x, +-y, +-z in turn for 2 s
each; holds when the object moves less than 5 cm and turns less than 15 degrees
(:class:`~graspnet_torch.physics.config.PhysicsCfg` holds every number, and what is pinned beside it).

The run: the model (:mod:`graspnet_torch.physics.model`; compiled once per robot, object and
protocol, each check a copy with the bodies the posture places set: the same to the last bit as a
model written for that posture) starts in the grasp posture, its actuators
commanded to the squeeze posture (the trial's ``squeeze`` where the result has one, else the grasp
posture itself); a settle of ``settle_s`` without external force, whose object shift and turn are
reported; then from that settled state, each in turn and each from the same state, the external
force m g (times ``force_scale``) at the object's centre of mass along +x, -x, +y, -y, +z, -z for
``push_s``. A push holds when, at its end, the object's centre of mass lies less than
``max_shift_mm`` from where the settle left it and the object has turned less than
``max_turn_deg``; a push already past either bound stops early (it has failed).
"""

from __future__ import annotations

import copy
import json
import math
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.physics.config import DIRECTIONS, PhysicsCfg
from graspnet_torch.physics.model import OBJECT_BODY, grasp_mjcf, posed_bodies, quaternion
from graspnet_torch.robot.robot import Posture, Robot, load_robot
from graspnet_torch.solver.api import as_problem
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["PhysicsReport", "check_until_failure", "simulate_grasp"]

CHECK_EVERY_S = 0.1  # how often a push looks whether it has already failed
MODELS = 8  # compiled models kept per robot (one per object and protocol)
_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # robot -> {(object, protocol): MjModel}
G = 9.81


@dataclass(frozen=True)
class PhysicsReport:
    """What the physics check found.

    Attributes:
        directions: push direction ('+x', '-x', '+y', '-y', '+z', '-z', world frame) -> whether
            the grasp held the object through it; in that order, those run (every push, unless
            ``until_failure`` stopped at one that failed).
        shifts_mm, turns_deg: per direction, how far the object's centre of mass moved and how much
            it turned during that push (when it stopped early: by then).
        settle_shift_mm, settle_turn_deg: the object's shift and turn during the settle.
        moved_while_settling: the settle moved it more than ``settle_max_shift_mm``.
        protocol: the protocol's numbers (:meth:`PhysicsCfg.protocol`).
        wall_time_s: the check's wall time (model build, compile and simulation).
    """

    directions: dict[str, bool]
    shifts_mm: dict[str, float]
    turns_deg: dict[str, float]
    settle_shift_mm: float
    settle_turn_deg: float
    moved_while_settling: bool
    protocol: dict = field(default_factory=dict)
    wall_time_s: float = 0.0

    @property
    def holds(self) -> int:
        """In how many directions the grasp held."""
        return sum(self.directions.values())

    @property
    def of(self) -> int:
        """How many pushes the protocol has (6; the report may list fewer: ``until_failure``)."""
        return len(DIRECTIONS)

    @property
    def held_all(self) -> bool:
        """Whether the grasp held the object through every push of the protocol."""
        return self.holds == self.of

    def to_dict(self) -> dict:
        """``{"physics": {...}}``: the result file's ``physics`` entry (docs/physics.md)."""
        return {"physics": {"holds": self.holds, "of": self.of, "pushes_run": len(self.directions),
                            "directions": dict(self.directions),
                            "settle_shift_mm": round(self.settle_shift_mm, 3),
                            "settle_turn_deg": round(self.settle_turn_deg, 3),
                            "moved_while_settling": self.moved_while_settling, "protocol": dict(self.protocol)}}


def _mujoco():
    try:
        import mujoco
    except ImportError:
        raise ConfigError("the physics check needs MuJoCo: pip install mujoco") from None
    return mujoco


def _turn_deg(q0: np.ndarray, q1: np.ndarray) -> float:
    """The angle (degrees) between two orientations given as unit quaternions (w, x, y, z)."""
    return math.degrees(2.0 * math.acos(min(1.0, abs(float(np.dot(q0, q1))))))


def _postures(robot: Robot, result: GraspResult, posture: Posture | None) -> tuple[Posture, Posture]:
    """The start (grasp) and commanded (squeeze) postures."""
    if posture is not None:
        return posture, posture
    best = result.best
    start = trial_posture(robot, best)
    squeeze = best.fields.get("squeeze")
    return start, (trial_posture(robot, squeeze) if squeeze else start)


def simulate_grasp(problem: GraspProblem | str | Path, result: GraspResult, cfg: PhysicsCfg | None = None,
                   posture: Posture | None = None, robot: Robot | None = None) -> PhysicsReport:
    """Check in MuJoCo whether a grasp holds the problem's object (the module docstring's protocol).

    Args:
        problem: a :class:`GraspProblem`, a problem file or a shipped task's name (as ``gt.solve``
            takes); it must have an object, which starts at its pose.
        result: the grasp: its reported trial's posture is the start, and its ``squeeze`` posture
            (where given) what the fingers are commanded to; the palm (a free hand) or the body
            joints stay where the reported posture puts them.
        cfg: the protocol (None: :class:`PhysicsCfg`'s defaults, DexGraspBench's).
        posture: a posture to start from and command instead of the result's (the result's
            squeeze is then not used).
        robot: the robot (None: the problem's, loaded from its config).
    Returns:
        the report; ``report.to_dict()`` is the result file's ``{"physics": ...}``.
    """
    mujoco = _mujoco()
    t0 = time.perf_counter()
    cfg = cfg or PhysicsCfg()
    problem = as_problem(problem)
    if problem.object is None:
        raise ProblemError(f"{problem.source}: the physics check needs an object; this problem has none")
    if result.robot != problem.robot:
        raise ProblemError(f"{problem.source}: the result is for robot '{result.robot}', the problem for "
                           f"'{problem.robot}'")
    robot = robot or load_robot(problem.robot_cfg or problem.robot)
    start, target = _postures(robot, result, posture)
    model = _model(mujoco, robot, problem.object, start, target, cfg)
    for name, T in posed_bodies(robot, start).items():  # where this posture puts them (model.py)
        body = model.body(name).id
        model.body_pos[body], model.body_quat[body] = T[:3, 3], quaternion(T[:3, :3])
    data = mujoco.MjData(model)
    mujoco.mj_setConst(model, data)
    values, goals = robot.joint_values(start), robot.joint_values(target)
    for j in range(model.njnt):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            data.qpos[model.jnt_qposadr[j]] = values.get(model.joint(j).name, 0.0)
    for a in range(model.nu):
        data.ctrl[a] = goals.get(model.actuator(a).name, 0.0)
    mujoco.mj_forward(model, data)
    body = model.body(OBJECT_BODY).id

    def pose() -> tuple[np.ndarray, np.ndarray]:
        return data.xipos[body].copy(), data.xquat[body].copy()

    p0, q0 = pose()
    _run(mujoco, model, data, cfg.settle_s)
    p1, q1 = pose()
    settle_shift = float(np.linalg.norm(p1 - p0)) * 1000.0
    settle_turn = _turn_deg(q0, q1)

    kind = mujoco.mjtState.mjSTATE_INTEGRATION
    settled = np.empty(mujoco.mj_stateSize(model, kind))
    mujoco.mj_getState(model, data, settled, kind)
    force = cfg.force_scale * cfg.object_mass_kg * G
    directions, shifts, turns = {}, {}, {}
    for k, name in enumerate(DIRECTIONS):
        mujoco.mj_setState(model, data, settled, kind)
        mujoco.mj_forward(model, data)
        push = np.zeros(6)
        push[k // 2] = force if k % 2 == 0 else -force
        data.xfrc_applied[body] = push  # at the body's centre of mass, world frame
        shift, turn = _push(mujoco, model, data, cfg, body, p1, q1)
        data.xfrc_applied[body] = 0.0
        shifts[name], turns[name] = shift, turn
        directions[name] = bool(shift < cfg.max_shift_mm and turn < cfg.max_turn_deg)
        if cfg.until_failure and not directions[name]:
            break
    return PhysicsReport(directions, shifts, turns, settle_shift, settle_turn,
                         bool(settle_shift > cfg.settle_max_shift_mm), cfg.protocol(), time.perf_counter() - t0)


def _model(mujoco, robot: Robot, obj, start: Posture, target: Posture, cfg: PhysicsCfg):
    """A copy of the compiled model of ``robot`` holding ``obj`` under ``cfg`` (its posed bodies as
    some posture left them: the caller sets them), compiled once per robot, object and protocol
    (``MODELS`` per robot kept) and copied for each check (a check changes its copy's bodies)."""
    key = (json.dumps(obj.to_mapping(), sort_keys=True), cfg)
    models = _MODELS.setdefault(robot, {})
    if key not in models:
        if len(models) >= MODELS:
            models.pop(next(iter(models)))
        models[key] = mujoco.MjModel.from_xml_string(grasp_mjcf(robot, obj, start, target, cfg).xml)
    return copy.copy(models[key])


def check_until_failure(problem: GraspProblem | str | Path, result: GraspResult,
                        robot: Robot | None = None) -> PhysicsReport:
    """The check a search for grasps that hold every push runs: :func:`simulate_grasp` with the
    default protocol, stopping at the first push that fails (``PhysicsCfg.until_failure``): the same
    verdict on every push held, sooner on a grasp that fails one."""
    return simulate_grasp(problem, result, PhysicsCfg(until_failure=True), robot=robot)


def _run(mujoco, model, data, seconds: float) -> None:
    steps = round(seconds / model.opt.timestep)
    if steps:
        mujoco.mj_step(model, data, nstep=steps)


def _push(mujoco, model, data, cfg: PhysicsCfg, body: int, p1: np.ndarray, q1: np.ndarray) -> tuple[float, float]:
    """Step one push; (shift mm, turn deg) of the object from the settled pose at its end (or once
    it is past a bound)."""
    steps = round(cfg.push_s / model.opt.timestep)
    chunk = max(1, round(CHECK_EVERY_S / model.opt.timestep))
    done = 0
    while True:
        n = min(chunk, steps - done)
        mujoco.mj_step(model, data, nstep=n)
        done += n
        shift = float(np.linalg.norm(data.xipos[body] - p1)) * 1000.0
        turn = _turn_deg(q1, data.xquat[body])
        if done >= steps or shift >= cfg.max_shift_mm or turn >= cfg.max_turn_deg or not np.isfinite(shift):
            return (shift if np.isfinite(shift) else math.inf), turn
