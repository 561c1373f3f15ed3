"""What an environment answers (:mod:`graspnet_torch.solver.environment`): the verdict on
configurations (:class:`Evaluation`) and the float64 report of trials (:class:`Report`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import torch
from torch import Tensor

__all__ = ["Done", "Evaluation", "Report"]

Done = Callable[[Tensor], Tensor]  # done(converged (B,) bool) -> (B,) bool: the rows that may stop
# Evaluation's fields, in order
_PARTS = ("error", "finger_errors", "joints", "collisions", "alignment", "config", "contact_errors")


@dataclass
class Evaluation:
    """An environment's verdict on T configurations (leading dimension T everywhere).

    Attributes:
        error: (T,) metres: E of eq. 3, the sum of the fingertip errors.
        finger_errors: (T, F) per contact finger, or None.
        joints: (T, F, j) finger joints chosen for each contact finger, or None.
        collisions: (T,) collision count, or None when the environment has no collision component.
        alignment: (T,) a gripper's |n_gripper . n_object| (eq. 24), or None; then ``error`` is d
            (eq. 26) and the reinforcement's base is (R1 + R2) / 2 (eq. 29).
        config: (T, n) the configuration that was evaluated: the proposal itself, or where the
            environment settled it (a gripper's settling steps). :meth:`Environment.evaluate` always
            sets it; evaluations built otherwise (a polish, a report) may leave it None.
        contact_errors: (T, F) the surface model's grasp test per contact finger: the pad's
            distance to its contact, metres, infinite where the pad faces outside the cone
            (``finger_errors`` adds the pad's hinge, which starts inside the cone, for the search
            to aim there); None: ``finger_errors`` is the test.
    """

    error: Tensor
    finger_errors: Tensor | None = None
    joints: Tensor | None = None
    collisions: Tensor | None = None
    alignment: Tensor | None = None
    config: Tensor | None = None
    contact_errors: Tensor | None = None

    def grasp_errors(self) -> Tensor | None:
        """(T, F) what the grasp test compares with the tolerance per contact finger (None: no fingers)."""
        return self.contact_errors if self.contact_errors is not None else self.finger_errors

    def tensors(self) -> dict[str, Tensor]:
        """The parts that are present, by name."""
        parts = ((name, getattr(self, name)) for name in _PARTS)
        return {name: value for name, value in parts if value is not None}

    def where(self, mask: Tensor, other: Evaluation) -> Evaluation:
        """Per trial: this evaluation where ``mask`` (T,) is true, else ``other``."""
        out = {}
        for name, mine in self.tensors().items():
            theirs = getattr(other, name)  # a part only one side has (a polished row's config) is dropped
            out[name] = None if theirs is None else torch.where(mask.view(-1, *([1] * (mine.dim() - 1))), mine, theirs)
        return replace(self, **out)

    def put(self, trials: Tensor, part: Evaluation, config: Tensor) -> Evaluation:
        """This evaluation with rows ``trials`` (B,) replaced by ``part`` (an evaluation of B
        trials); ``config`` (T, n): the proposals, the evaluated configuration of the rows a
        part without ``config`` leaves unrefined."""
        out = {}
        for name, theirs in part.tensors().items():
            mine = getattr(self, name)
            base = (config if name == "config" else None) if mine is None else mine
            out[name] = base.index_copy(0, trials, theirs)
        if part.config is None:
            out["config"] = None
        return replace(self, **out)

    def clone(self) -> Evaluation:
        return replace(self, **{k: v.clone() for k, v in self.tensors().items()})


@dataclass
class Report:
    """The float64 report of T trials (:meth:`Environment.report`).

    Attributes:
        fields: per trial, the result fields the environment adds to the common core (INTERFACE.md:
            the palm pose, finger joints and fingertip errors; arm joints; a gripper's d, alignment
            and points).
        evaluation: the float64 evaluation of the reported configurations without collisions (the
            caller adds the FCL counts): what the reinforcement and ``grasped`` are recomputed from.
        error_mm: (T,) the error each trial is ranked by (E of eq. 3, or a gripper's d), millimetres.
        landed: (T,) every contact within ``solver.tolerance_mm`` (a gripper: d within it, aligned):
            the grasp but for collisions.
    """

    fields: list[dict]
    evaluation: Evaluation
    error_mm: list[float]
    landed: list[bool]

    def split(self, runs: int) -> list[Report]:
        """The reports of consecutive groups of ``runs`` trials (a batch of problems: one per
        problem, in order)."""
        ev = {k: v.split(runs) for k, v in self.evaluation.tensors().items()}
        return [Report(self.fields[a: a + runs], Evaluation(**{k: v[p] for k, v in ev.items()}),
                       self.error_mm[a: a + runs], self.landed[a: a + runs])
                for p, a in enumerate(range(0, len(self.fields), runs))]
