"""The one registry of robot kinds: a row per kind carries everything that kind adds.

A robot's kind (:attr:`RobotCfg.kind <graspnet_torch.robot.config.RobotCfg.kind>`: ``hand``,
``arm_hand``, ``gripper``) is read from its config's structure. Code that differs by kind asks the
kind's :class:`RobotKind` row (:func:`robot_kind`), never the kind's name: the problem keys a
problem file may give, how the palm is placed (the :class:`~graspnet_torch.robot.heads.Head`:
a free palm pose or a body chain's joints), the environment that solves it, its random problems,
its walk space for sequences, whether closure contact sets exist for it.

The registry lives here, in the robot layer, so that every layer can ask it; the rows are made in
:mod:`graspnet_torch.solver.kinds`, one module per kind, above the solver whose environments they name,
and registered when :mod:`graspnet_torch` is imported (which every import of one of its modules
does first). Adding a robot kind: one module in ``graspnet_torch/solver/kinds/`` with its row.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["KINDS", "ProblemSchema", "RobotKind", "register_kind", "robot_kind"]


@dataclass(frozen=True)
class ProblemSchema:
    """What a problem file gives for a robot, by the robot's kind.

    Attributes:
        targets: ``contacts`` (one point per finger) or ``points`` (a gripper's two object points).
        bounds: the key of the search bounds a problem may give: ``palm_bounds`` (a free hand's
            palm box), ``bounds`` (an arm's joint ranges), or None.
        reference: the key that places a reference posture's palm: ``palm_pose`` (a free hand) or
            ``arm_joints`` (an arm), or None (no reference posture).
        extra: other keys this kind takes (a gripper's ``approach`` configuration).
    """

    targets: str
    bounds: str | None
    reference: str | None
    extra: tuple[str, ...] = ()

    @property
    def keys(self) -> tuple[str, ...]:
        """The kind-specific keys this robot's problems may give."""
        own = (self.targets, self.bounds, "reference" if self.reference else None, *self.extra)
        return tuple(k for k in own if k is not None)


@dataclass(frozen=True)
class RobotKind:
    """Everything one kind of robot adds (one row of :data:`KINDS`).

    The callables are typed loosely here (the robot layer cannot name the classes of the layers
    above it); each is documented with what it takes and returns.

    Attributes:
        name: the kind, as :attr:`RobotCfg.kind` names it.
        description: one line for people (what the kind is; the docs list it).
        schema: the kind-specific keys of its problem files.
        head: ``Robot -> Head``: how its palm is placed (:mod:`graspnet_torch.robot.heads`).
        environment: its :class:`~graspnet_torch.solver.environment.Environment` subclass.
        random_problem: ``(robot, seed, n_fingers) -> GraspProblem``, a random reachable contact
            problem (``gt.random_reachable_problem``); None: the kind has no contacts.
        posed_problem: ``(robot, seed, n_fingers) -> (GraspProblem, Posture)``: a random posture
            and the problem it solves (what a posture proposal model learns from).
        walk_space: ``Robot -> WalkSpace``: the box its posture walks in for a random sequence;
            None: no sequences.
        closure: whether contact sets closed on an object (known collision-free) are made for it.
        min_fingers: the fewest fingers a robot of this kind needs (0: none; it grasps otherwise).
    """

    name: str
    description: str
    schema: ProblemSchema
    head: Callable[[Any], Any]
    environment: type
    posed_problem: Callable[..., Any]
    random_problem: Callable[..., Any] | None = None
    walk_space: Callable[[Any], Any] | None = None
    closure: bool = False
    min_fingers: int = 0


KINDS: dict[str, RobotKind] = {}
"""Kind name -> its row, filled by :mod:`graspnet_torch.solver.kinds` (see the module docstring)."""


def register_kind(row: RobotKind) -> RobotKind:
    """Add (or replace) a kind's row; returns it."""
    KINDS[row.name] = row
    return row


def robot_kind(robot: Any) -> RobotKind:
    """The row of a robot's kind: ``robot`` is a kind's name or anything with a ``kind`` (a
    :class:`~graspnet_torch.robot.Robot` or its :class:`~graspnet_torch.robot.config.RobotCfg`)."""
    name = robot if isinstance(robot, str) else robot.kind
    row = KINDS.get(name)
    if row is None:
        known = ", ".join(sorted(KINDS)) or "none registered (import graspnet_torch)"
        raise KeyError(f"no robot kind '{name}' (known: {known})")
    return row
