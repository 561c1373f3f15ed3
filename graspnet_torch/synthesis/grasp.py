"""A synthesized grasp (:func:`~graspnet_torch.synthesis.synthesize.synthesize_grasps`): its problem,
contact set, quality, solve, physics check, type and the links that touch."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from graspnet_torch.quality import GraspQuality
from graspnet_torch.solver import GraspResult
from graspnet_torch.synthesis.drafts import ContactSet
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["SynthesizedGrasp"]


@dataclass
class SynthesizedGrasp:
    """One grasp of an object.

    Attributes:
        problem: the grasp problem the contact set made (contacts in the object frame).
        candidate: the contact set and the sampled posture that touches it.
        quality: its grasp quality (epsilon, least singular value, force closure).
        result: the surface-model solve of ``problem``.
        physics: the physics check of ``result`` (a :class:`gt.PhysicsReport`; None: not asked for).
        links: the links that touch the object (a precision grasp: its fingers' pad links; a power
            grasp: every link within 1 mm of it, the palm's among them).
        type: "precision" (pads on the object) or "power" (the palm or a link other than a pad's
            touches; :mod:`~graspnet_torch.synthesis.power`).
    """

    problem: GraspProblem
    candidate: ContactSet
    quality: GraspQuality
    result: GraspResult
    physics: Any = None
    links: tuple[str, ...] = ()
    type: str = "precision"

    @property
    def contacts(self) -> np.ndarray:
        """(k, 3) the contacts, world."""
        return self.candidate.contacts

    @property
    def success(self) -> bool:
        return bool(self.result.success)

    @property
    def holds(self) -> int | None:
        """Of the physics check's pushes, how many held (None: not checked)."""
        return None if self.physics is None else sum(self.physics.directions.values())

    def to_dict(self) -> dict:
        """The grasp as JSON: every field of its solve's result (:meth:`GraspResult.to_dict` without
        the other trials: the reported trial's fields at the top, a surface grasp's pregrasp and
        squeeze included; ``trials_run``: how many trials the solve ran), then its ``type`` and the
        ``links`` that touch, its ``fingers``, its
        ``contacts`` (object frame, as a problem file lists them) and ``contacts_world`` (m), its
        ``quality``, ``holds`` and the physics check's ``report.to_dict()["physics"]`` (None: not
        checked); a gripper's: its ``fingers`` the marked points, ``points`` (object frame) in place of
        ``contacts``; ``normal_angles_deg``: each pad's (a gripper: the line between its points')
        angle to the inward normal (None: a power grasp's contacts, no pad aimed)."""
        data = {k: v for k, v in self.result.to_dict().items() if k != "trials"}
        physics = None if self.physics is None else self.physics.to_dict().get("physics")
        points = self.problem.points
        data.update({"trials_run": len(self.result.trials), "type": self.type, "links": list(self.links),
                     "fingers": list(self.candidate.fingers),
                     "contacts": [{"finger": c.finger, "position": np.asarray(c.position, dtype=np.float64).tolist()}
                                  for c in self.problem.contacts],
                     **({} if points is None else {"points": np.asarray(points, dtype=np.float64).tolist()}),
                     "normal_angles_deg": [None if np.isnan(a) else float(a)
                                           for a in np.asarray(self.candidate.angles_deg, dtype=np.float64)],
                     "contacts_world": np.asarray(self.contacts, dtype=np.float64).tolist(),
                     "quality": {"epsilon": float(self.quality.epsilon),
                                 "min_singular_value": float(self.quality.min_singular_value),
                                 "force_closure": bool(self.quality.force_closure)},
                     "success": self.success, "holds": self.holds, "physics": physics})
        return data
