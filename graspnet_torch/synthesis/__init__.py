"""Grasp synthesis: contact sets chosen on an object so that the hand can touch them with its
pads (:mod:`~graspnet_torch.synthesis.candidates`), ranked by grasp quality and solved
(:mod:`~graspnet_torch.synthesis.synthesize`)."""

from __future__ import annotations

from graspnet_torch.synthesis.candidates import ContactSet, pad_contact_sets
from graspnet_torch.synthesis.synthesize import SynthesizedGrasp, rank_sets, synthesize_grasps

__all__ = ["ContactSet", "SynthesizedGrasp", "pad_contact_sets", "rank_sets", "synthesize_grasps"]
