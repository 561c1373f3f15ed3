"""Training a posture proposal model: the FCNN's competition (winner takes all) over K heads.

For a sample with known configuration c (normalised by the data's scale: z), head k's distance
is ``d_k = |z_k - z|^2`` (an angle whose bounds span a full turn is compared modulo 2 pi); the
loss is ``(1 - eps) d_winner + eps mean_k d_k`` (eps small: no head is left without gradient,
so none dies), plus the scores' regression onto ``log(d_k + 1e-3)``. Adam, cosine-decayed
learning rate, fixed seed; the state (model, optimiser, step, generator) is resumable.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from graspnet_torch.proposal.data import ProposalData
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg

__all__ = ["ProposalTrainer", "head_distances"]

EPS = 0.05


def head_distances(model: PostureProposal, targets: Tensor, mask: Tensor, configs: Tensor) -> tuple[Tensor, Tensor]:
    """(B, K) each head's squared distance to the known configurations (normalised units, angles
    that span a full turn modulo 2 pi), and the heads' scores (B, K)."""
    z, score = model.normalised(targets, mask)
    diff = (model.config_mean + model.config_std * z) - configs.unsqueeze(1)  # raw units
    diff = torch.where(model.periodic, torch.remainder(diff + math.pi, 2 * math.pi) - math.pi, diff)
    return ((diff / model.config_std) ** 2).sum(-1), score


class ProposalTrainer:
    """Trains one model on one data set (``data``: training samples; ``held_out``: validation).

    Attributes:
        model, optimizer, steps_done, generator (the batch draws).
    """

    def __init__(self, model: PostureProposal, data: ProposalData, held_out: ProposalData, cfg: ProposalCfg,
                 seed: int = 0):
        self.model, self.data, self.held_out, self.cfg = model, data, held_out, cfg
        self.optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr)
        self.steps_done = 0
        self.generator = torch.Generator().manual_seed(seed)

    def lr(self, step: int) -> float:
        return self.cfg.lr * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * min(step / self.cfg.steps, 1.0))))

    def step(self) -> float:
        """One Adam step on a random batch; returns the loss."""
        idx = torch.randint(len(self.data), (min(self.cfg.batch, len(self.data)),), generator=self.generator)
        d, score = head_distances(self.model, self.data.targets[idx], self.data.mask[idx], self.data.configs[idx])
        wta = d.min(1).values
        loss = (1 - EPS) * wta.mean() + EPS * d.mean() + 0.1 * ((score - torch.log(d.detach() + 1e-3)) ** 2).mean()
        for group in self.optimizer.param_groups:
            group["lr"] = self.lr(self.steps_done)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.steps_done += 1
        return float(loss.detach())

    @torch.no_grad()
    def validate(self) -> dict[str, float]:
        """On the held-out samples: the nearest head's RMS distance per variable (normalised units:
        1 is the data's spread), median and 90th percentile, and how often the best-scored head is
        the nearest."""
        h = self.held_out
        d, score = head_distances(self.model, h.targets, h.mask, h.configs)
        best = (d.min(1).values / self.model.n).sqrt()
        return {"median": float(best.median()), "p90": float(best.quantile(0.9)),
                "score_hits_pct": float((score.argmin(1) == d.argmin(1)).float().mean() * 100)}

    def state_dict(self) -> dict:
        return {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict(),
                "steps_done": self.steps_done, "generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.steps_done = int(state["steps_done"])
        self.generator.set_state(state["generator"])
