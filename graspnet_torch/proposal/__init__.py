"""Posture proposal models: a problem's targets -> configurations the search starts from."""

from graspnet_torch.proposal.checkpoint import load_proposal, posture_checkpoint, proposal_of, save_proposal
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg
from graspnet_torch.proposal.starts import Proposals, proposal_starts, proposals

__all__ = ["PostureProposal", "ProposalCfg", "Proposals", "load_proposal", "posture_checkpoint", "proposal_of",
           "proposal_starts", "proposals", "save_proposal"]
