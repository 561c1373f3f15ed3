"""The posture proposal model: a problem's targets -> K configurations of the search variables.

What the SRV loop searches (a free hand's palm pose in its search frame, an arm's joints, the
MANUS's nine joints) is proposed in one pass, as the FCNN proposes a finger's joints:

    targets (B, S, 3), mask (B, S)  ->  (B, K, n) configurations, (B, K) scores

The targets are what the environment gives (:meth:`~graspnet_torch.solver.environment.Environment.
proposal_input`): one slot per robot finger (zeros and mask 0 where the problem has no contact for
it) for robots with fingers, the two object points for a gripper, expressed in the environment's
frame: for a free hand its search frame, which is made from the contacts, so the same contacts
moved and turned anywhere give the same input and the proposals moved and turned with them.

Grasps have many solutions, so the model is multimodal: K heads ("modular experts"), trained with
the FCNN's competition (winner takes all: each sample trains only the head nearest its known
configuration), so the heads spread over the solutions. A score per head, trained to predict the
head's own error, ranks them; the solver ranks them by the environment's error anyway.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from graspnet_torch.settings import build, setting

__all__ = ["PostureProposal", "ProposalCfg"]


@dataclass(frozen=True)
class ProposalCfg:
    """The proposal model and its training (Hydra group ``posture``).

    Attributes:
        heads: K, proposals per problem.
        hidden: units of the shared hidden layers.
        samples: random posed problems drawn for training (plus a tenth more held out).
        steps: Adam steps.
        batch: samples per step.
        lr: Adam's learning rate (cosine-decayed to a hundredth).
        val_every: steps between held-out evaluations (TensorBoard, progress bar).
    """

    heads: int = setting(16, lo=1, hi=256)
    hidden: tuple[int, ...] = setting((256, 256, 256), lo=1, hi=4096)
    samples: int = setting(20_000, lo=16, hi=10_000_000)
    steps: int = setting(6_000, lo=1, hi=10_000_000)
    batch: int = setting(512, lo=1, hi=1_000_000)
    lr: float = setting(2e-3, lo=0.0, lo_open=True, hi=1.0)
    val_every: int = setting(250, lo=1, hi=10_000_000)

    @classmethod
    def from_mapping(cls, d: dict | None, where: str = "posture") -> ProposalCfg:
        return build(cls, d, where)


class PostureProposal(nn.Module):
    """S target slots -> K configurations of n search variables, and a score per configuration.

    Args:
        slots: S, target slots (robot fingers, or a gripper's two points).
        n: search variables.
        cfg: sizes.

    Buffers (set from the training data, saved with the weights): ``target_mean``, ``target_std``
    (3,): the targets' scale; ``config_mean``, ``config_std`` (n,): the configurations' (the
    heads answer in these units, so every search variable weighs alike in the competition).
    """

    def __init__(self, slots: int, n: int, cfg: ProposalCfg = ProposalCfg()):
        super().__init__()
        self.slots, self.n, self.heads = slots, n, cfg.heads
        layers: list[nn.Module] = []
        width = 4 * slots
        for h in cfg.hidden:
            layers += [nn.Linear(width, h), nn.SiLU()]
            width = h
        self.trunk = nn.Sequential(*layers)
        self.out = nn.Linear(width, cfg.heads * (n + 1))
        self.register_buffer("target_mean", torch.zeros(3))
        self.register_buffer("target_std", torch.ones(3))
        self.register_buffer("config_mean", torch.zeros(n))
        self.register_buffer("config_std", torch.ones(n))
        self.register_buffer("periodic", torch.zeros(n, dtype=torch.bool))

    def normalised(self, targets: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """targets (B, S, 3), mask (B, S) -> the heads' configurations in normalised units
        (B, K, n) and their scores (B, K) (predicted log error; lower is better)."""
        t = (targets - self.target_mean) / self.target_std * mask.unsqueeze(-1)
        x = torch.cat([t.flatten(1), mask], 1)
        y = self.out(self.trunk(x)).view(-1, self.heads, self.n + 1)
        return y[..., : self.n], y[..., self.n]

    def forward(self, targets: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """targets (B, S, 3), mask (B, S) -> configurations (B, K, n) in the search's units and
        scores (B, K) (lower: the model expects it nearer a grasp)."""
        z, score = self.normalised(targets, mask)
        return self.config_mean + self.config_std * z, score

    def fit_scales(self, targets: Tensor, mask: Tensor, configs: Tensor, periodic: Tensor) -> None:
        """Set the buffers from training data: targets (N, S, 3), mask (N, S), configs (N, n),
        periodic (n,) bool."""
        self.periodic.copy_(periodic)
        on = mask.bool()
        points = targets[on]
        self.target_mean.copy_(points.mean(0))
        self.target_std.copy_(points.std(0).clamp_min(1e-6))
        self.config_mean.copy_(configs.mean(0))
        self.config_std.copy_(configs.std(0).clamp_min(1e-6))
