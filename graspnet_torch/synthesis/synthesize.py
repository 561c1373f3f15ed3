"""An object in, grasps out: contact sets the hand can touch with its pads
(:func:`~graspnet_torch.synthesis.candidates.pad_contact_sets`), ranked by grasp quality, each
solved as a problem of the "surface" contact model, the successes (optionally checked in physics)
returned best first.

Ranking: force-closure sets first, then by Ferrari-Canny epsilon (friction ``FRICTION``, the
object's centre as the centre of mass), then by the grasp matrix's least singular value.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import GraspQuality, grasp_quality
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.solver import GraspResult, solve, solve_many
from graspnet_torch.synthesis.candidates import FRICTION, ContactSet, pad_contact_sets, placeholder_problem
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["FRICTION", "SynthesizedGrasp", "rank_sets", "synthesize_grasps"]



@dataclass
class SynthesizedGrasp:
    """One grasp of an object.

    Attributes:
        problem: the grasp problem the contact set made (contacts in the object frame).
        candidate: the contact set and the sampled posture that touches it.
        quality: its grasp quality (epsilon, least singular value, force closure).
        result: the surface-model solve of ``problem``.
        physics: the physics check of ``result`` (a :class:`gt.PhysicsReport`; None: not asked for).
    """

    problem: GraspProblem
    candidate: ContactSet
    quality: GraspQuality
    result: GraspResult
    physics: Any = None

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
        squeeze included; ``trials_run``: how many trials the solve ran), then its ``fingers``, its
        ``contacts`` (object frame, as a problem file lists them) and ``contacts_world`` (m), its
        ``quality``, ``holds`` and the physics check's ``report.to_dict()["physics"]`` (None: not
        checked)."""
        data = {k: v for k, v in self.result.to_dict().items() if k != "trials"}
        physics = None if self.physics is None else self.physics.to_dict().get("physics")
        data.update({"trials_run": len(self.result.trials), "fingers": [c.finger for c in self.problem.contacts],
                     "contacts": [{"finger": c.finger, "position": np.asarray(c.position, dtype=np.float64).tolist()}
                                  for c in self.problem.contacts],
                     "contacts_world": np.asarray(self.contacts, dtype=np.float64).tolist(),
                     "quality": {"epsilon": float(self.quality.epsilon),
                                 "min_singular_value": float(self.quality.min_singular_value),
                                 "force_closure": bool(self.quality.force_closure)},
                     "success": self.success, "holds": self.holds, "physics": physics})
        return data


def rank_sets(sets: Sequence[ContactSet], obj: Shape, friction: float = FRICTION
              ) -> list[tuple[ContactSet, GraspQuality]]:
    """The sets with their qualities, best first (module docstring)."""
    if not sets:
        return []
    q = grasp_quality(np.stack([s.contacts for s in sets]), np.stack([s.normals for s in sets]),
                      np.tile(np.asarray(obj.pose[:3], dtype=np.float64), (len(sets), 1)), friction)
    eps, sig, fc = (np.asarray(a, dtype=np.float64) for a in (q.epsilon, q.min_singular_value, q.force_closure))
    order = sorted(range(len(sets)), key=lambda i: (-fc[i], -eps[i], -sig[i]))
    return [(sets[i], GraspQuality(float(eps[i]), float(sig[i]), bool(fc[i]))) for i in order]


def synthesize_grasps(robot: Robot, obj: Shape, n_grasps: int = 5,
                      fingers: Sequence[str] = ("thumb", "index", "middle"), candidates: int = 64, seed: int = 0,
                      physics: Callable[..., Any] | None = None, solve_top: int | None = None, trials: int = 8,
                      solver: dict | None = None, stats: dict | None = None) -> list[SynthesizedGrasp]:
    """Up to ``n_grasps`` grasps of ``obj`` by ``robot``'s ``fingers``, best first.

    ``candidates`` contact sets are drawn (:func:`pad_contact_sets`, ``seed``) and ranked
    (:func:`rank_sets`); the best ``solve_top`` of them (default ``2 n_grasps``) are solved as one
    batch (:func:`gt.solve_many`, ``trials`` learners each, ``solver`` settings over
    ``contact_model: surface``); the successes are checked in MuJoCo where ``physics`` and
    returned in rank order. ``physics``: a check ``physics(problem, result, robot=robot)`` returning
    a report with ``directions`` (push -> held), i.e. ``gt.simulate_grasp`` (this layer sits below
    the physics layer, so the check is passed in); with it, grasps holding more pushes first.
    ``stats``, if given, receives the generator's counts and the timings (s).
    """
    if n_grasps < 1 or candidates < 1:
        raise ProblemError(f"synthesize_grasps: n_grasps {n_grasps} and candidates {candidates} must be >= 1")
    t0 = time.perf_counter()
    counts: dict = {}
    sets = pad_contact_sets(robot, obj, candidates, fingers, seed, stats=counts)
    t1 = time.perf_counter()
    ranked = rank_sets(sets, obj)[: solve_top or 2 * n_grasps]
    problems = [placeholder_problem(robot, obj, fingers, s.contacts) for s, _ in ranked]
    settings = {"contact_model": "surface", **(solver or {})}
    t2 = time.perf_counter()
    results = _solve(problems, trials, seed, settings)
    t3 = time.perf_counter()
    grasps = [SynthesizedGrasp(p, s, q, r) for p, (s, q), r in zip(problems, ranked, results, strict=True)
              if r.success]
    if physics is not None:
        for g in grasps:
            g.physics = physics(g.problem, g.result, robot=robot)
        grasps.sort(key=lambda g: -(g.holds or 0))  # stable: rank order within a count
    t4 = time.perf_counter()
    if stats is not None:
        stats.update(counts, generate_s=t1 - t0, rank_s=t2 - t1, solve_s=t3 - t2, physics_s=t4 - t3,
                     solved=len(problems), succeeded=len(grasps))
    return grasps[:n_grasps]


def _solve(problems: list[GraspProblem], trials: int, seed: int, settings: dict) -> list[GraspResult]:
    """The problems solved as one batch, else one at a time where the batch is refused."""
    if not problems:
        return []
    try:
        return solve_many(problems, trials=trials, seed=seed, solver=settings)
    except ProblemError:
        return [solve(p, trials=trials, seed=seed, solver=settings) for p in problems]
