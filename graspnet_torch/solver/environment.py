"""What the closed loop drives: an environment turns configurations into an evaluation.

The loop (``solver/loop.py``) never knows which robot it drives. A robot-and-problem pair becomes
an environment with

- ``n``, ``lower``, ``upper``: the size of the configuration the network chooses and its bounds
  (a free palm: 6 pose values; an arm: its joints);
- ``evaluate(config (T, n)) -> Evaluation``: the error the reinforcement is built from (E of
  eq. 3) and optional parts (per-finger errors, the finger joints the FCNN chose, collision
  counts);
- ``finish(config, evaluation) -> Evaluation``: a last refinement of what is reported;
- ``report(...)``: the result fields of each trial, recomputed in float64.

Rewards (R1-R4, eq. 20-23) are functions of the evaluation, the iteration and the budget
(:class:`graspnet_torch.rewards.Reward`). :func:`build_environment` picks the environment of a
robot and a problem; a new kind of robot is a new environment, never an edit of the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Protocol

import torch
from torch import Tensor

__all__ = ["Environment", "Evaluation"]


@dataclass
class Evaluation:
    """An environment's verdict on T configurations (leading dimension T everywhere).

    Attributes:
        error: (T,) metres: E of eq. 3, the sum of the fingertip errors.
        finger_errors: (T, F) per contact finger, or None.
        joints: (T, F, j) finger joints chosen for each contact finger, or None.
        collisions: (T,) collision count, or None when the environment has no collision component.
    """

    error: Tensor
    finger_errors: Tensor | None = None
    joints: Tensor | None = None
    collisions: Tensor | None = None

    def tensors(self) -> dict[str, Tensor]:
        """The parts that are present, by name."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def where(self, mask: Tensor, other: Evaluation) -> Evaluation:
        """Per trial: this evaluation where ``mask`` (T,) is true, else ``other``."""
        out = {}
        for name, mine in self.tensors().items():
            theirs = getattr(other, name)
            out[name] = torch.where(mask.view(-1, *([1] * (mine.dim() - 1))), mine, theirs)
        return replace(self, **out)

    def clone(self) -> Evaluation:
        return replace(self, **{k: v.clone() for k, v in self.tensors().items()})


class Environment(Protocol):
    """What the loop needs from a robot-specific environment."""

    n: int
    lower: Tensor  # (n,)
    upper: Tensor  # (n,)

    def evaluate(self, config: Tensor) -> Evaluation:
        """(T, n) configurations -> their evaluation."""
        ...
