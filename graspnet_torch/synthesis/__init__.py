"""Grasp synthesis: contact sets chosen on an object so that the hand can touch them with its
pads (:mod:`~graspnet_torch.synthesis.candidates`), ranked by grasp quality and solved
(:mod:`~graspnet_torch.synthesis.synthesize`), and power grasps where the pads' do not hold
(:mod:`~graspnet_torch.synthesis.power`: the palm on the object, the fingers wrapped around it);
beside it, a planner with no contact reasoning
(:mod:`~graspnet_torch.synthesis.baseline`: random palm poses, fingers closed until they touch)."""

from __future__ import annotations

from graspnet_torch.synthesis.baseline import BaselineGrasp, baseline_grasps
from graspnet_torch.synthesis.candidates import ContactSet, pad_contact_sets
from graspnet_torch.synthesis.synthesize import SynthesizedGrasp, rank_sets, synthesize_grasps

__all__ = ["BaselineGrasp", "ContactSet", "SynthesizedGrasp", "baseline_grasps", "pad_contact_sets", "rank_sets",
           "synthesize_grasps"]
