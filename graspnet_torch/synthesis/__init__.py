"""Grasp synthesis: contact sets chosen on an object so that the hand can touch them with its
pads (:mod:`~graspnet_torch.synthesis.candidates`), ranked by grasp quality and solved
(:mod:`~graspnet_torch.synthesis.synthesize`)."""

from __future__ import annotations

from graspnet_torch.synthesis.candidates import ContactSet, pad_contact_sets

__all__ = ["ContactSet", "pad_contact_sets"]
