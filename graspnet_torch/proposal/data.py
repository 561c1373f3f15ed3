"""Training data of a posture proposal model: random posed problems of a robot, each with its
environment's view of the targets and the configuration of the posture that made it."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.config import SolverCfg

__all__ = ["ProposalData", "proposal_data"]


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


def proposal_data(robot: Robot, finger_ik: FingerIK | None, n: int, seed: int, solver: SolverCfg | None = None
                  ) -> ProposalData:
    """n samples from :func:`~graspnet_torch.tasks.random.random_posed_problem` (seeds ``seed``,
    ``seed + 1``, ...): each problem's environment (built with ``solver``'s settings) gives the
    targets in its frame and the posture's configuration in its search variables
    (:meth:`~graspnet_torch.solver.environment.Environment.whole_of`)."""
    from graspnet_torch.solver.environments import build_environment
    from graspnet_torch.tasks.random import random_posed_problem

    solver = solver or SolverCfg()
    targets, masks, configs = [], [], []
    for k in range(n):
        problem, posture = random_posed_problem(robot, seed + k)
        env = build_environment(robot, problem, finger_ik, solver)
        t, m = env.proposal_input()
        targets.append(t[0])
        masks.append(m[0])
        configs.append(env.whole_of(posture)[0, : env.n].float())
    return ProposalData(torch.stack(targets), torch.stack(masks), torch.stack(configs))
