"""The reported grasp is one that passes what was asked: ``verify=physics`` and ``reach=true``.

:func:`verify_result` goes through a result's successful trials in the order ``result.best``
ranks them (a solver's own choice first, then collision-free ones, then the smallest error), checks
each (``physics``: the grasp holds its object through every push of
:func:`~graspnet_torch.physics.simulate_grasp`; ``reach``: :func:`~graspnet_torch.motion.plan_reach`
finds a motion to it), stops at the first that passes every check, and reports that one
(``result.chosen``). Each checked trial keeps its ``physics`` report in its fields; the reported
trial gets ``verified`` (what was checked, how many trials, which passed) and the result the
reported trial's motion. When none passes, the best is reported as before, with its checks.

:func:`check_verify` holds the refusals before any work: the physics check needs the problem's
object and MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.motion import ReachCfg, StateLayout, Trajectory, plan_reach
from graspnet_torch.physics import DIRECTIONS, PhysicsCfg, simulate_grasp
from graspnet_torch.settings import clip
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["REQUIRED_HOLDS", "TrialCheck", "Verification", "check_verify", "motion_line", "no_motion", "ranking",
           "verify_result"]

REQUIRED_HOLDS = len(DIRECTIONS)  # a grasp passes the physics check when it holds through every push (6/6)
NO_GRASP = "no grasp to reach (the solve did not succeed)"


@dataclass(frozen=True)
class TrialCheck:
    """One checked trial: its index, whether it passed every check, and (failed) the first check it
    failed, in one line."""

    trial: int
    passed: bool
    why: str = ""

    def to_dict(self) -> dict:
        return {"trial": self.trial, "passed": self.passed, **({"why": self.why} if self.why else {})}


@dataclass(frozen=True)
class Verification:
    """What :func:`verify_result` did: the checks asked (``physics``, ``reach``), each checked trial
    in the order checked, and the reported trial's index."""

    what: tuple[str, ...]
    checks: list[TrialCheck] = field(default_factory=list)
    chosen: int = 0

    @property
    def checked(self) -> int:
        return len(self.checks)

    @property
    def passed(self) -> bool:
        """Whether the reported trial passed every check asked."""
        return any(c.passed for c in self.checks)

    def to_dict(self) -> dict:
        """The reported trial's ``verified`` field (docs/physics.md)."""
        return {"what": list(self.what), "checked": self.checked, "passed": self.passed,
                "trials": [c.to_dict() for c in self.checks]}

    def summary(self) -> str:
        """One line: which trial passed and how many were checked, or that none did."""
        what = " and ".join(_describe(w) for w in self.what)
        if self.passed:
            return f"verified: trial {self.chosen} passes {what}; {self.checked} trial(s) checked, best first"
        if not self.checked:
            return f"{what} not checked: no successful trial; the best (trial {self.chosen}) is reported"
        return f"none of the {self.checked} successful trial(s) checked passes {what}; the best (trial " \
               f"{self.chosen}) is reported with its checks"


def _describe(what: str) -> str:
    return f"physics (holds {REQUIRED_HOLDS}/{len(DIRECTIONS)})" if what == "physics" else "reach (a motion found)"


def check_verify(problem: GraspProblem) -> None:
    """``verify=physics``'s refusals before any work: the problem has an object, MuJoCo is installed."""
    if problem.object is None:
        raise ProblemError(f"verify=physics: {problem.source} has no object (the physics check pushes the "
                           f"problem's object in the grasp); give a problem with an object, or verify=none")
    try:
        import mujoco  # noqa: F401  (only whether it imports)
    except ImportError:
        raise ConfigError("verify=physics needs MuJoCo: pip install mujoco (or verify=none)") from None


def ranking(result: GraspResult) -> list[int]:
    """The successful trials' indices in the order ``result.best`` would choose them: the trial a
    solver chose (``result.chosen``) first, then collision-free before colliding, the smallest
    error first (ties: the lower index)."""
    return [k for k in _ranked(result) if result.trials[k].success]


def _ranked(result: GraspResult) -> list[int]:
    """Every trial's index, ``result.best``'s key: the chosen one, then successful, collision-free,
    smallest error."""
    trials = result.trials
    return sorted(range(len(trials)), key=lambda k: (k != result.chosen, not trials[k].success,
                                                     trials[k].collisions > 0, trials[k].error_mm))


def motion_line(motion: Trajectory, cfg: ReachCfg) -> str:
    """A reach motion in one line: its rows, length and planning time, or why there is none."""
    if motion.found:
        return (f"reach motion: {len(motion.times)} rows, {motion.times[-1]:.2f} s long, planned in "
                f"{motion.planning_time_s:.2f} s ({motion.planner}; collision-free at {cfg.resolution_deg:g} deg / "
                f"{cfg.resolution_mm:g} mm)")
    return f"no reach motion: {motion.reason}"


def verify_result(robot, problem: GraspProblem, result: GraspResult, physics: PhysicsCfg | None,
                  reach: ReachCfg | None, limit: int | None = None,
                  planner: Callable[..., Trajectory] = plan_reach, log: Callable[[str], None] | None = print
                  ) -> Verification:
    """Report the first successful trial, in :func:`ranking`'s order, that passes every check asked.

    Args:
        robot: the problem's robot.
        problem: the problem ``result`` solves.
        result: changed in place: each checked trial's fields get ``physics`` (its report,
            :meth:`~graspnet_torch.physics.PhysicsReport.to_dict`); ``chosen`` becomes the first
            trial that passes (none: the best, as before); the reported trial's fields get
            ``verified`` (:meth:`Verification.to_dict`); with ``reach``, ``result.trajectory`` is the
            reported trial's motion.
        physics: check that the grasp holds its object (all :data:`REQUIRED_HOLDS` pushes) under
            this protocol; None: not checked.
        reach: check that a reach motion to the grasp is found (``planner(problem, result, reach,
            robot)``, :func:`~graspnet_torch.motion.plan_reach`); None: not checked.
        limit: the most trials checked (None: every successful trial).
        log: called with one line per checked trial (None: quiet).
    Returns:
        what was checked and which trial is reported.
    """
    what = tuple(name for name, cfg in (("physics", physics), ("reach", reach)) if cfg is not None)
    best = _ranked(result)[0]  # result.best's index
    order = ranking(result)[:limit]
    checks: list[TrialCheck] = []
    motions: dict[int, Trajectory] = {}
    chosen = best
    for k in order:
        one = replace(result, chosen=k)  # the same trials, trial k reported
        why, said = "", []
        if physics is not None:
            report = simulate_grasp(problem, one, physics, robot=robot).to_dict()["physics"]
            result.trials[k].fields["physics"] = report
            said.append(f"physics holds {report['holds']}/{report['of']}")
            if report["holds"] < REQUIRED_HOLDS:
                why = said[-1]
        if reach is not None and not why:
            motions[k] = motion = planner(problem, one, reach, robot)
            said.append(motion_line(motion, reach))
            if not motion.found:
                why = f"reach: {clip(motion.reason, 200)}"
        checks.append(TrialCheck(k, not why, why))
        if log is not None:
            log(f"trial {k}: {'; '.join(said)}")
        if not why:
            chosen = k
            break
    result.chosen = chosen
    if reach is not None:
        if chosen not in motions:  # none passed and the best's motion was not planned: as without checks
            motions[chosen] = planner(problem, result, reach, robot) if result.success else no_motion(robot, reach)
            if log is not None:
                log(motion_line(motions[chosen], reach))
        result.trajectory = motions[chosen]
    verification = Verification(what, checks, chosen)
    result.trials[chosen].fields["verified"] = verification.to_dict()
    return verification


def no_motion(robot, reach: ReachCfg) -> Trajectory:
    """The motion of a result without a grasp: none (``found`` false, the reason)."""
    layout = StateLayout.of(robot, reach.palm_speed)
    return Trajectory.missing(list(layout.names), layout.revolute, NO_GRASP, 0.0)
