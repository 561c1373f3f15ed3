"""Posture proposal models: a problem's targets -> configurations the search starts from (the model,
its checkpoints, its training); where the trials start and the training data, through the
environment contract: :mod:`graspnet_torch.solver.proposals`."""

from graspnet_torch.proposal.checkpoint import load_proposal, posture_checkpoint, proposal_of, save_proposal
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg

# re-exported only until solver/api.py imports it from graspnet_torch.solver.proposals (then this line and its
# ignore_imports line in pyproject.toml go)
from graspnet_torch.solver.proposals import proposal_starts

__all__ = ["PostureProposal", "ProposalCfg", "load_proposal", "posture_checkpoint", "proposal_of", "proposal_starts",
           "save_proposal"]
