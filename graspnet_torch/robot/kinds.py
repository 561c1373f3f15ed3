"""The robot kinds: what each kind of robot is, the keys its problem files give, and its limits.

A robot's kind (:attr:`RobotCfg.kind <graspnet_torch.robot.config.RobotCfg.kind>`: ``hand``,
``arm_hand``, ``gripper``) is read from its config's structure. Code that differs by kind asks a
table of its own layer, each keyed by the kind's name and written out in full (no registration):
this module's :data:`KINDS` (the problem keys, the fewest fingers, closure contact sets), the
heads (:data:`graspnet_torch.robot.heads.HEADS`: how the palm is placed), the random problems
(:data:`graspnet_torch.tasks.random.PROBLEMS`) and the environments that solve it
(:data:`graspnet_torch.solver.environments.ENVIRONMENTS`). Adding a robot kind: a row in each.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["KINDS", "ProblemSchema", "RobotKind", "robot_kind"]


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
    """What one kind of robot is (one row of :data:`KINDS`).

    Attributes:
        name: the kind, as :attr:`RobotCfg.kind` names it.
        description: one line for people (what the kind is; the docs list it).
        schema: the kind-specific keys of its problem files.
        closure: whether contact sets closed on an object (known collision-free) are made for it.
        min_fingers: the fewest fingers a robot of this kind needs (0: none; it grasps otherwise).
    """

    name: str
    description: str
    schema: ProblemSchema
    closure: bool = False
    min_fingers: int = 0


KINDS: dict[str, RobotKind] = {row.name: row for row in (
    RobotKind("hand", "a free palm with fingers: 6 pose values, the FCNN places the fingers",
              ProblemSchema("contacts", "palm_bounds", "palm_pose"), closure=True, min_fingers=2),
    RobotKind("arm_hand", "fingers on a body chain: the arm's joints carry the palm, the FCNN places the fingers",
              ProblemSchema("contacts", "bounds", "arm_joints", ("start",)), min_fingers=2),
    RobotKind("gripper", "a body chain with two marked gripper points (MANUS): its joints put them on the "
              "object's two points", ProblemSchema("points", None, None, ("approach", "start"))),
)}
"""Kind name -> its row."""


def robot_kind(robot: Any) -> RobotKind:
    """The row of a robot's kind: ``robot`` is a kind's name or anything with a ``kind`` (a
    :class:`~graspnet_torch.robot.Robot` or its :class:`~graspnet_torch.robot.config.RobotCfg`)."""
    name = robot if isinstance(robot, str) else robot.kind
    row = KINDS.get(name)
    if row is None:
        raise KeyError(f"no robot kind '{name}' (known: {', '.join(sorted(KINDS))})")
    return row
