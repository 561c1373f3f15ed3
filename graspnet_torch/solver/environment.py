"""The environment contract: everything a solver (srv, paper, cmaes, dls, ``solve_many``) may ask of
a robot-and-problem pair, with one signature each.

A solver never knows which robot it drives. The configuration it searches is ``n`` numbers within
``lower``/``upper`` (a free palm: 6 pose values; an arm: its joints; a mobile manipulator: base and
arm); the environment turns configurations into an :class:`Evaluation` (E of eq. 3, per-finger
errors, the finger joints the FCNN chose, collision counts, a gripper's alignment), says what the
reinforcement's base is (eq. 14, or eq. 29 for a gripper) and when a configuration is a grasp,
polishes configurations by least squares over the *whole* configuration x (the configuration with
the contact fingers' joints; what ``solver=dls`` moves), and reports each trial in float64 with the
result fields it adds to the common core (INTERFACE.md).

The contract comes in three parts, one module each, so that each concern reads on its own:

==========================================  ====================================================
:class:`~.env_search.SearchPart`            the search: evaluate, the reinforcement's base,
                                            ``grasped``, finish and the in-loop polish, warm
                                            starts, a proposal model's input
:class:`~.env_whole.WholePart`              the whole configuration x: random and warm-started
                                            x, its local solve (the one Levenberg-Marquardt),
                                            the result of a solve
:class:`~.env_report.ReportPart`            the float64 report, the exact collision check of a
                                            grasp, and what a kind knows before an environment
                                            exists (``check``, ``unreachable``, ``describe``,
                                            ``summary``, ``columns``, ``marks``: class methods)
==========================================  ====================================================

:class:`Environment` is the three together with the attributes every solver reads. A new kind of
robot is a new environment named in :data:`graspnet_torch.solver.environments.ENVIRONMENTS`, never
an edit of a solver; a part's methods with a default (``polish``, ``centre``, ``unreachable``, ...)
need no code where the default holds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from torch import Tensor

from graspnet_torch.solver.env_report import ReportPart
from graspnet_torch.solver.env_search import SearchPart
from graspnet_torch.solver.env_whole import WholePart
from graspnet_torch.solver.evaluation import Done, Evaluation, Report

if TYPE_CHECKING:
    from graspnet_torch.robot.robot import Robot
    from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["Done", "Environment", "Evaluation", "Report"]


class Environment(SearchPart, WholePart, ReportPart):
    """What every solver may call. Settings reach an environment when it is built.

    Attributes:
        robot: the robot; problems: the problems (one, or a batch's), in the environment's frame;
            world_problems: the same as given (the world: what :meth:`report` answers in).
        n: size of the searched configuration.
        lower, upper: (n,) bounds, or (T, n) per trial for a batch of problems.
        problem_index: (T,) each trial's problem in a batch of problems (trial t on problem
            t // runs), or None (one problem).
        subsets: ``evaluate(config[idx], idx)`` allowed: once most trials have stopped, the loop
            evaluates the others only.
        polishes: the environment has an in-loop polish (:meth:`polish`).
        counts_collisions: its evaluations count collisions (the reward shapes them and the
            problem has something to collide with).
        on_surface: its contact fingers' pads go onto the object's surface (the surface contact
            model): its in-loop polish lands against the object by design, so it starts from the
            first iteration as where nothing collides (``solver.polish.from_r_free``).
        error_key: the result field (JSON key) of the error a trial is ranked by.
        shared_slots: how many of the configuration's last columns are joints several fingers
            share (a free hand's; 0: the robot holds them, or has none).
    """

    error_key: ClassVar[str] = "total_error_mm"
    shared_slots: int = 0
    robot: Robot
    problems: list[GraspProblem]
    world_problems: list[GraspProblem]
    n: int
    lower: Tensor
    upper: Tensor
    problem_index: Tensor | None = None
    subsets: bool = False
    polishes: bool = False
    counts_collisions: bool = False
    on_surface: bool = False
