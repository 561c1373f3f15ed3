"""Evaluation and reinforcement signals (paper eq. 3, 14, 15, 20-29).

All functions are elementwise over leading batch dimensions; errors and distances in metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import torch
from torch import Tensor

from graspnet_torch.settings import build, setting

__all__ = [
    "NoiseCfg",
    "Reward",
    "RewardCfg",
    "Scored",
    "add_noise",
    "manus_reward",
    "r1",
    "r2",
    "r3",
    "r4",
    "total_error",
]


@dataclass(frozen=True)
class RewardCfg:
    """Reinforcement (Hydra group ``reward/``): R_1 = 1 - tanh(a E) (eq. 14 / 20), E the total
    fingertip error in metres, and its collision-shaped forms (eq. 21-23).

    Attributes:
        kind: 'r1' (no collision term), 'r2' (R_1 / 2 on a collision), 'r3' (shaping:
            R_1 / (1 + i / p) on a collision) or 'r4' (R_1 / (1 + c^beta i / p), c collisions).
        a: slope of the evaluation (the paper gives a = 1.5 for the arm, none for the hand; with
            a = 1 the default threshold r > 0.99 means E < 10 mm).
        beta: exponent of the collision count in R_4 (paper: 0.25).
        p: the iteration count at which R_3 reaches R_2 (paper: 2000, its iteration budget);
            ``None``: the solver's ``max_iterations``.
    """

    kind: str = setting("r1", choices=("r1", "r2", "r3", "r4"))
    a: float = setting(1.0, lo=0.0, lo_open=True, hi=1e4)
    beta: float = setting(0.25, lo=0.0, lo_open=True, hi=100.0)
    p: int | None = setting(None, lo=1, hi=10_000_000)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "reward") -> RewardCfg:
        return build(cls, d, where)


@dataclass(frozen=True)
class NoiseCfg:
    """Sensor noise on the reinforcement: r + N(0, sigma) (eq. 15)."""

    sigma: float = setting(0.0, lo=0.0, hi=100.0)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "noise") -> NoiseCfg:
        return build(cls, d, where)


class Scored(Protocol):
    """What a reward reads of an evaluation (:class:`~graspnet_torch.solver.environment.Evaluation`):
    ``error`` (T,) metres, ``collisions`` (T,) or None, ``alignment`` (T,) or None."""

    error: Tensor
    collisions: Tensor | None
    alignment: Tensor | None


def total_error(desired: Tensor, actual: Tensor) -> Tensor:
    """Eq. 3: E_k = sum_i |PX_i^D - PX_i^M| over the fingers. (..., F, 3), (..., F, 3) -> (...)."""
    return torch.linalg.vector_norm(desired - actual, dim=-1).sum(-1)


def r1(error: Tensor, a: float = 1.0) -> Tensor:
    """Eq. 14 / 20: R_1 = 1 - tanh(a E) (h = tanh, the paper's choice), in (0, 1]."""
    return 1.0 - torch.tanh(a * error)


def r2(reward: Tensor, collisions: Tensor) -> Tensor:
    """Eq. 21: R_1 halved whenever there is a collision."""
    return torch.where(collisions > 0, reward / 2, reward)


def r3(reward: Tensor, collisions: Tensor, iteration: int, max_iterations: int) -> Tensor:
    """Eq. 22 (shaping): R_1 / (1 + i / p) when there is a collision."""
    return torch.where(collisions > 0, reward / (1 + iteration / max_iterations), reward)


def r4(reward: Tensor, collisions: Tensor, iteration: int, max_iterations: int, beta: float = 0.25) -> Tensor:
    """Eq. 23 (shaping graded by the number c of collisions): R_1 / (1 + c^beta i / p)."""
    c = collisions.to(reward.dtype)
    return torch.where(collisions > 0, reward / (1 + c.clamp(min=1) ** beta * (iteration / max_iterations)), reward)


def manus_reward(gripper: Tensor, target: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Eq. 24-29: the MANUS two-point criterion.

    gripper, target: (..., 2, 3) the two marked points on the gripper and on the object.
    Returns (R, R_1, R_2, d): R_1 = |n_gripper . n_object| (24), d = min(d_1, d_2) (26-28) over the two
    pairings of the points, R_2 = 1 - tanh(d) (25), R = (R_1 + R_2) / 2 (29).
    """
    n_g = torch.nn.functional.normalize(gripper[..., 1, :] - gripper[..., 0, :], dim=-1)
    n_o = torch.nn.functional.normalize(target[..., 1, :] - target[..., 0, :], dim=-1)
    rr1 = (n_g * n_o).sum(-1).abs()
    d1 = (target[..., 0, :] - gripper[..., 0, :]).norm(dim=-1) + (target[..., 1, :] - gripper[..., 1, :]).norm(dim=-1)
    d2 = (target[..., 1, :] - gripper[..., 0, :]).norm(dim=-1) + (target[..., 0, :] - gripper[..., 1, :]).norm(dim=-1)
    d = torch.minimum(d1, d2)
    rr2 = 1.0 - torch.tanh(d)
    return (rr1 + rr2) / 2, rr1, rr2, d


def add_noise(reward: Tensor, sigma: float, generator: torch.Generator | None = None) -> Tensor:
    """Eq. 15: r + N(0, sigma_n), modelling low-quality sensors (not clipped)."""
    if sigma <= 0:
        return reward
    return reward + sigma * torch.randn(reward.shape, generator=generator, dtype=reward.dtype, device=reward.device)


class Reward:
    """The reinforcement of the ``reward`` group, as a function of an evaluation, the iteration i
    (1-based) and the budget p: R_1 (eq. 20), or R_2, R_3, R_4 (eq. 21-23) from its collision
    count. An evaluation without a collision component counts no collision. The base that
    collisions shape is R_1 = 1 - tanh(a E) (eq. 14), or the environment's
    (:meth:`~graspnet_torch.solver.environment.Environment.reward_base`: a gripper's eq. 29).

    Args:
        cfg: kind, a, beta and p (``None``: p = ``budget``).
        budget: the loop's iteration budget.
        base: ``base(evaluation, a) -> (T,)``, the reinforcement before shaping (None: R_1).
    """

    def __init__(self, cfg: RewardCfg, budget: int, base: Callable[[Scored, float], Tensor] | None = None):
        self.cfg = cfg
        self.p = cfg.p if cfg.p is not None else budget
        self.base = base

    def __call__(self, evaluation: Scored, iteration: int | Tensor) -> Tensor:
        """(T,) reinforcement, noise-free; ``iteration`` an int or (T,) per trial."""
        r = r1(evaluation.error, self.cfg.a) if self.base is None else self.base(evaluation, self.cfg.a)
        if self.cfg.kind == "r1" or evaluation.collisions is None:
            return r
        c = evaluation.collisions
        if self.cfg.kind == "r2":
            return r2(r, c)
        if isinstance(iteration, Tensor):
            iteration = iteration.to(r.dtype)
        if self.cfg.kind == "r3":
            return r3(r, c, iteration, self.p)
        return r4(r, c, iteration, self.p, self.cfg.beta)
