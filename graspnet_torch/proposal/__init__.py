"""Posture proposal models: a problem's targets -> configurations the search starts from (the model,
its checkpoints, its training); where the trials start and the training data, through the
environment contract: :mod:`graspnet_torch.solver.proposals`."""

from __future__ import annotations

from graspnet_torch.proposal.checkpoint import load_proposal, posture_checkpoint, proposal_of, save_proposal
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg

__all__ = ["PostureProposal", "ProposalCfg", "load_proposal", "posture_checkpoint", "proposal_of", "save_proposal"]
