"""Training data of a posture proposal model: targets as an environment gives them and the
configurations that reach them (made by :func:`graspnet_torch.solver.proposals.proposal_data`)."""

from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor

__all__ = ["ProposalData"]


@dataclass
class ProposalData:
    """N samples: ``targets`` (N, S, 3) and ``mask`` (N, S) as the environment gives them
    (:meth:`~graspnet_torch.solver.environment.Environment.proposal_input`), ``configs`` (N, n) the
    search variables of the posture that made each problem, float32."""

    targets: Tensor
    mask: Tensor
    configs: Tensor

    def __len__(self) -> int:
        return self.configs.shape[0]

    def split(self, n: int) -> tuple[ProposalData, ProposalData]:
        """The first n samples and the rest."""
        return (ProposalData(self.targets[:n], self.mask[:n], self.configs[:n]),
                ProposalData(self.targets[n:], self.mask[n:], self.configs[n:]))
