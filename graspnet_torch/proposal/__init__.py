"""Posture proposal models: a problem's targets -> configurations the search starts from (the model,
its checkpoints, its training); where the trials start and the training data, through the
environment contract: :mod:`graspnet_torch.solver.proposals`."""

from __future__ import annotations

from typing import Any

from graspnet_torch.proposal.checkpoint import load_proposal, posture_checkpoint, proposal_of, save_proposal
from graspnet_torch.proposal.model import PostureProposal, ProposalCfg

__all__ = ["PostureProposal", "ProposalCfg", "load_proposal", "posture_checkpoint", "proposal_of", "proposal_starts",
           "save_proposal"]


def proposal_starts(*args: Any, **kwargs: Any) -> Any:
    """Moved: :func:`graspnet_torch.solver.proposals.proposal_starts` (the solver's). Kept here only
    until ``solver/api.py`` imports it from there; then this function and its ``ignore_imports``
    lines in pyproject.toml go. (Imported when called: the solver imports this package.)"""
    from graspnet_torch.solver.proposals import proposal_starts as starts

    return starts(*args, **kwargs)
