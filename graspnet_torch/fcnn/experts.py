"""A finger's set of expert networks (paper section 3), evaluated in one batched call.

Each expert is an MLP 3 -> H -> H -> n (linear input and output layers, tanh hidden layers; the
paper's H = 35, n = 4): fingertip position in the finger's base frame -> joint angles. All experts
of a finger share stacked weights of shape (E_max, ...); ``n_active`` of them exist (experts are
created incrementally up to ``max_experts``), and every call evaluates all active experts with
batched matrix products, never a Python loop over experts.

Inputs and outputs are normalised by fixed affine maps (workspace centre/scale, joint-range
centre/half-width). Those are linear and could be folded into the first and last layers; keeping
them apart makes the weights' scale independent of the finger's size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from graspnet_torch.settings import setting

__all__ = ["ExpertSet", "ExpertSetCfg"]


@dataclass(frozen=True)
class ExpertSetCfg:
    """Sizes of a finger's expert set.

    Attributes:
        hidden: units in each of the two hidden layers (paper: 35).
        max_experts: most experts a finger may create (paper: 4 to 6 emerged).
    """

    hidden: int = setting(35, lo=1, hi=1024)
    max_experts: int = setting(6, lo=1, hi=64)


class ExpertSet(nn.Module):
    """Up to ``max_experts`` MLPs of one finger, with their representative postures.

    Args:
        n_joints: joints of the finger (outputs per expert).
        x_center: (3,) affine normalisation of fingertip positions: its centre,
        x_scale: (3,) and its scale.
        q_lower: (n,) lower joint limits; outputs are normalised to the range,
        q_upper: (n,) upper joint limits.
        cfg: sizes.
    """

    def __init__(self, n_joints: int, x_center: Tensor, x_scale: Tensor, q_lower: Tensor, q_upper: Tensor,
                 cfg: ExpertSetCfg = ExpertSetCfg()):
        super().__init__()
        E, H, n = cfg.max_experts, cfg.hidden, n_joints
        self.cfg = cfg
        self.n_joints = n
        self.W1 = nn.Parameter(torch.zeros(E, 3, H))
        self.b1 = nn.Parameter(torch.zeros(E, 1, H))
        self.W2 = nn.Parameter(torch.zeros(E, H, H))
        self.b2 = nn.Parameter(torch.zeros(E, 1, H))
        self.W3 = nn.Parameter(torch.zeros(E, H, n))
        self.b3 = nn.Parameter(torch.zeros(E, 1, n))
        self.register_buffer("x_center", x_center.detach().clone().float().reshape(3))
        self.register_buffer("x_scale", x_scale.detach().clone().float().reshape(3))
        self.register_buffer("q_lower", q_lower.detach().clone().float().reshape(n))
        self.register_buffer("q_upper", q_upper.detach().clone().float().reshape(n))
        self.register_buffer("rep_postures", torch.zeros(E, n))
        self.register_buffer("active", torch.zeros(E, dtype=torch.bool))

    # ------------------------------------------------------------------ structure
    @property
    def n_active(self) -> int:
        return int(self.active.sum())

    @property
    def full(self) -> bool:
        return self.n_active >= self.cfg.max_experts

    def add_expert(self, rep_posture: Tensor, generator: torch.Generator | None = None) -> int:
        """Create the next expert with a fresh initialisation; returns its index."""
        if self.full:
            raise RuntimeError(f"expert set is full ({self.cfg.max_experts} experts)")
        e = self.n_active
        H, n = self.cfg.hidden, self.n_joints
        with torch.no_grad():
            for W, b, fan_in in ((self.W1, self.b1, 3), (self.W2, self.b2, H), (self.W3, self.b3, H)):
                bound = 1.0 / math.sqrt(fan_in)  # PyTorch's default Linear initialisation
                W[e].uniform_(-bound, bound, generator=generator)
                b[e].uniform_(-bound, bound, generator=generator)
            self.rep_postures[e] = rep_posture.detach().to(self.rep_postures).reshape(n)
            self.active[e] = True
        return e

    # ------------------------------------------------------------------ evaluation
    def _net(self, x: Tensor, W1: Tensor, b1: Tensor, W2: Tensor, b2: Tensor, W3: Tensor, b3: Tensor) -> Tensor:
        h = torch.tanh(torch.baddbmm(b1, x, W1))
        h = torch.tanh(torch.baddbmm(b2, h, W2))
        return torch.baddbmm(b3, h, W3)

    def normalize_x(self, x: Tensor) -> Tensor:
        return (x - self.x_center.to(x)) / self.x_scale.to(x)

    def normalize_q(self, q: Tensor) -> Tensor:
        lo, hi = self.q_lower.to(q), self.q_upper.to(q)
        return (q - (lo + hi) / 2) / ((hi - lo) / 2)

    def denormalize_q(self, u: Tensor) -> Tensor:
        lo, hi = self.q_lower.to(u), self.q_upper.to(u)
        return (lo + hi) / 2 + u * (hi - lo) / 2

    def forward(self, x: Tensor) -> Tensor:
        """Every active expert's joint angles for every target (not clamped).

        x: (B, 3) fingertip positions in the base frame -> (E_active, B, n).
        """
        E = self.n_active
        xn = self.normalize_x(x).unsqueeze(0).expand(E, -1, -1)
        params = [p[:E].to(x.dtype) for p in (self.W1, self.b1, self.W2, self.b2, self.W3, self.b3)]
        return self.denormalize_q(self._net(xn, *params))

    def forward_each(self, x: Tensor) -> Tensor:
        """Expert e on its own inputs x[e], normalised output (for training).

        x: (E_active, M, 3) -> (E_active, M, n) in normalised joint units.
        """
        E = x.shape[0]
        params = [p[:E] for p in (self.W1, self.b1, self.W2, self.b2, self.W3, self.b3)]
        return self._net(self.normalize_x(x), *params)

    def extra_repr(self) -> str:
        cfg = self.cfg
        return f"n_active={self.n_active}, max_experts={cfg.max_experts}, hidden={cfg.hidden}, n={self.n_joints}"
