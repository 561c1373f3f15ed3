"""An object in, grasps out: contact sets the hand can touch with its pads
(:func:`~graspnet_torch.synthesis.candidates.pad_contact_sets`), ranked by grasp quality, each
solved as a problem of the "surface" contact model, the successes (optionally checked in physics)
returned best first.

Ranking: force-closure sets first, then by Ferrari-Canny epsilon (friction ``FRICTION``, the
object's centre as the centre of mass), then by the grasp matrix's least singular value.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import GraspQuality, grasp_quality
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.kinds import robot_kind
from graspnet_torch.robot.opposition import default_fingers
from graspnet_torch.robot.robot import Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.solver import GraspResult, Solver, solve, solve_many
from graspnet_torch.solver.api import as_robot, settings_of
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.candidates import (
    FRICTION,
    ContactSet,
    SetCheck,
    pad_contact_sets,
    placeholder_problem,
)
from graspnet_torch.synthesis.drafts import iter_contact_drafts
from graspnet_torch.synthesis.grasp import SynthesizedGrasp
from graspnet_torch.synthesis.pairs import SAMPLES as SAMPLES_OF_PAIRS
from graspnet_torch.synthesis.pairs import WIDTH_TOL_M, PointPair, antipodal_pairs, jaw_width
from graspnet_torch.synthesis.power import power_grasps
from graspnet_torch.synthesis.reach import arm_palms, carried_hand, reach_sets
from graspnet_torch.synthesis.seat import SEATED_M, seat_pads
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["FRICTION", "START", "SynthesizedGrasp", "no_grasp_reason", "rank_sets", "synthesize_grasps"]

TRIES_PER_SET = 50  # palm poses drawn at most per contact set asked for (start="sampled")
LOOK_AHEAD = 2  # start="sampled": sampler batches drawn before a solve while no set in hand is force closure
# (when it came, on the 10 tuning objects, 64 sets, top 5, one process: 0 -> 2 took the s per grasp that holds
# 6/6 from 0.95 to 0.82 and the objects whose top grasp holds from 9 to 10; 3 and 5 gave 0.86 and 0.85)


def _rank_key(q: GraspQuality) -> tuple:
    """:func:`rank_sets`' order as a sort key: force closure, then epsilon, then the least singular value."""
    return (-q.force_closure, -q.epsilon, -q.min_singular_value)


def rank_sets(sets: Sequence[ContactSet], obj: Shape, friction: float = FRICTION
              ) -> list[tuple[ContactSet, GraspQuality]]:
    """The sets with their qualities, best first (module docstring)."""
    if not sets:
        return []
    q = grasp_quality(np.stack([s.contacts for s in sets]), np.stack([s.normals for s in sets]),
                      np.tile(np.asarray(obj.pose[:3], dtype=np.float64), (len(sets), 1)), friction)
    eps, sig, fc = (np.asarray(a, dtype=np.float64) for a in (q.epsilon, q.min_singular_value, q.force_closure))
    rated = [(s, GraspQuality(float(e), float(g), bool(f))) for s, e, g, f in zip(sets, eps, sig, fc, strict=True)]
    return sorted(rated, key=lambda sq: _rank_key(sq[1]))  # stable: drawing order within equal qualities


def synthesize_grasps(robot: Robot | RobotCfg | str | Path, obj: Shape, n_grasps: int = 5,
                      fingers: Sequence[str] | None = None, candidates: int = 64, seed: int = 0,
                      physics: Callable[..., Any] | None = None, solve_top: int | None = None, trials: int = 8,
                      solver: dict | None = None, stats: dict | None = None, start: str = "sampled",
                      obstacles: Sequence[Shape] = (), power: bool = True) -> list[SynthesizedGrasp]:
    """Up to ``n_grasps`` grasps of ``obj`` by ``robot``'s ``fingers``, best first (``robot``: a
    built robot, a shipped robot's name, a robot config or its YAML path; ``fingers`` None: the
    hand's opposing finger and its two nearest neighbours, found from its kinematics,
    :func:`~graspnet_torch.robot.opposition.default_fingers`).

    Contact sets are drawn (``seed``) and ranked by quality (:func:`rank_sets`), at most
    ``candidates`` of them solved, each as a problem of the surface contact model (``solver``
    settings over ``contact_model: surface``), and
    each success is checked in MuJoCo where ``physics`` is given: a check
    ``physics(problem, result, robot=robot)`` returning a report with ``directions`` (push ->
    held), i.e. ``gt.simulate_grasp`` (this layer sits below the physics layer, so the check is
    passed in). Returned: holding more pushes first (with physics), then in rank order.

    ``start``: where each posture's solve starts.

    - ``"sampled"`` (default): at the posture the sampler found touching the set, a warm start
      (:meth:`gt.Solver.solve <graspnet_torch.solver.session.Solver.solve>` with ``search=False``:
      Levenberg-Marquardt, one trial; a start that does not land is dropped). The drafts the
      sampler's batches bring (:func:`~graspnet_torch.synthesis.drafts.iter_contact_drafts`) wait in
      one pool, each checked (:class:`~graspnet_torch.synthesis.candidates.SetCheck`) only when it
      comes to the top, and the best checked set is solved next (rank order);
      while no set in the pool is force closure, up to ``LOOK_AHEAD`` more batches are drawn
      before a solve. The search ends once ``n_grasps`` grasps hold every push (without physics:
      once ``n_grasps`` succeed) or ``candidates`` sets were tried: the first verified grasp comes
      after the first batch or few.
    - ``"random"``: the paper's search from random starts: the ``candidates`` sets are drawn first,
      the best ``solve_top`` of them (default ``2 n_grasps``) solved as one batch
      (:func:`gt.solve_many`, ``trials`` learners each, ``solver.start: random``).
    - ``"proposal"``: that search with its trials started at the robot's learned posture
      proposals (``solver.start: proposal``; a robot without a proposal model starts at random,
      said once).

    ``solver`` settings given win over what ``start`` sets.

    ``power``: where the pads' grasps leave fewer than ``n_grasps`` holding every push (without
    physics: succeeding), a free hand's power grasps too (:mod:`~graspnet_torch.synthesis.power`),
    checked the same way; each grasp says its ``type`` and the ``links`` that touch.

    A hand on an arm (its config names its free ``hand``) draws its sets with that hand and keeps
    those the arm reaches (:mod:`~graspnet_torch.synthesis.reach`). A gripper with two marked points
    (MANUS) grasps antipodal point pairs as wide as its jaws (:mod:`~graspnet_torch.synthesis.pairs`,
    at most ``candidates``), the best ``solve_top`` (default ``2 n_grasps``) solved by the search
    (``trials`` learners each) among ``obstacles`` (a table); its jaws do not move: ``physics`` is
    refused. ``obstacles`` (a table under the object): a set whose links meet one is dropped as it
    is drawn, each solve counts them as collisions (the physics check leaves them out).

    ``stats``, if given, receives the sampler's counts, the timings (s: ``generate_s``, ``rank_s``,
    ``solve_s``, ``physics_s``; ``held_physics_s``: the part of ``physics_s`` spent on the checks
    that held every push; ``first_s``: to the first grasp that holds every push, None if none),
    ``solved``, ``succeeded``, ``held`` (power grasps' included) and the power search's ``power_*``.
    """
    if n_grasps < 1 or candidates < 1:
        raise ProblemError(f"synthesize_grasps: n_grasps {n_grasps} and candidates {candidates} must be >= 1")
    if start not in START:
        raise ProblemError(f"synthesize_grasps: start {start!r}: one of {', '.join(START)}")
    robot = as_robot(robot)
    gripper = robot_kind(robot).schema.targets == "points"
    if gripper and physics is not None:
        raise ProblemError(f"synthesize_grasps: robot {robot.name}: its jaws do not move (fixed marked points): "
                           f"there is no squeeze to check in physics; pass physics=None")
    run, settings = _search(gripper, start, solver, tuple(obstacles))
    if fingers is None:
        fingers = () if gripper else default_fingers(carried_hand(robot))
    t: dict = {"t0": time.perf_counter(), "generate_s": 0.0, "rank_s": 0.0, "solve_s": 0.0, "physics_s": 0.0,
               "held_physics_s": 0.0, "first_s": None, "solved": 0, "succeeded": 0, "held": 0, "unseated": 0}
    grasps = run(robot, obj, n_grasps, tuple(fingers), candidates, seed, physics, solve_top, trials, settings, t)
    done = t["held" if physics is not None else "succeeded"]
    if power and not gripper and not robot.has_body and done < n_grasps:
        check = None if physics is None else _timed(physics, t)
        grasps += power_grasps(robot, obj, n_grasps - done, seed, physics=check, obstacles=obstacles, stats=t)
    if physics is not None:
        grasps.sort(key=lambda g: -(g.holds or 0))  # stable: rank order within a count
    if stats is not None:
        stats.update({k: v for k, v in t.items() if k != "t0"})
    return grasps[:n_grasps]


START = ("sampled", "random", "proposal")


def no_grasp_reason(stats: dict) -> str:
    """Why :func:`synthesize_grasps` found no grasp, one line, from its ``stats``: no palm pose
    touched with every chosen pad (a hand on an arm: or none that the arm reached), none of those
    that did faced it with nothing inside the object, or the sets drawn were solved and none landed;
    and, where power grasps were drawn, what became of them."""
    reason = _pads_reason(stats)
    if "power_tried" not in stats:
        return reason
    return (f"{reason}; power grasps: of {stats['power_tried']} palm poses on the object {stats['power_touching']} "
            f"touched with 2 fingers or more, {stats['power_clean']} of those with nothing inside it, none in force "
            f"closure")


def _pads_reason(stats: dict) -> str:
    """:func:`no_grasp_reason` for the pads' grasps."""
    tried, touching, clean = stats.get("tried", 0), stats.get("touching", 0), stats.get("clean", 0)
    if stats.get("pairs") == 0:
        return (f"no grasp found: no antipodal pair {stats['width_mm']:.1f} mm apart (within "
                f"{WIDTH_TOL_M * 1000:g} mm) among {tried} surface points: the gripper's jaws are that far apart and "
                f"do not move")
    if stats.get("reached") == 0:
        return f"no grasp found: the arm reached none of {tried} palm poses around the object (out of its reach?)"
    if not touching:
        return (f"no grasp found: of {tried} palm poses none put every chosen finger's pad on the object's surface "
                f"(too large, too small or too thin for the hand?)")
    if not clean:
        return (f"no grasp found: {touching} of {tried} palm poses touched with every chosen pad, none with every pad "
                f"within the cone and nothing inside the object")
    unseated = stats.get("unseated", 0)
    return (f"no grasp found: {stats.get('solved', 0)} contact sets solved, none landed on its contacts"
            + (f" with its pads on the surface ({unseated} landed with a pad link off it by over "
               f"{SEATED_M * 1000:g} mm)" if unseated else ""))


def _check(g: SynthesizedGrasp, robot: Robot, physics: Callable[..., Any] | None, t: dict) -> None:
    """Check a grasp in physics (where asked), timed, counted in ``t["held"]`` where it holds every push."""
    if physics is not None:
        g.physics = _timed(physics, t)(g.problem, g.result, robot=robot)


def _search(gripper: bool, start: str, solver: dict | None, obstacles: tuple[Shape, ...]
            ) -> tuple[Callable[..., list[SynthesizedGrasp]], dict]:
    """The search of :func:`synthesize_grasps` (a gripper's pairs, the sampled or the searched
    solves) and its solver settings."""
    if gripper:
        return functools.partial(_pairs, obstacles=obstacles), dict(solver or {})
    settings = {"contact_model": "surface", **({} if start == "sampled" else {"start": start}), **(solver or {})}
    return functools.partial(_sampled if start == "sampled" else _random, obstacles=obstacles), settings


def _pad_links(hand: Robot, fingers: Sequence[str]) -> tuple[str, ...]:
    """The links that carry ``fingers``' pads, in order, each once."""
    return tuple(dict.fromkeys(hand.pads[f].link for f in fingers))


def _timed(physics: Callable[..., Any], t: dict) -> Callable[..., Any]:
    """``physics`` timed into ``t["physics_s"]``, a check that holds every push counted in
    ``t["held"]`` (and ``t["held_physics_s"]``, ``t["first_s"]``)."""

    def check(problem: GraspProblem, result: GraspResult, robot: Robot) -> Any:
        t1 = time.perf_counter()
        report = physics(problem, result, robot=robot)
        spent = time.perf_counter() - t1
        t["physics_s"] += spent
        if sum(report.directions.values()) == report.of:
            t["held"] += 1
            t["held_physics_s"] += spent
            if t["first_s"] is None:
                t["first_s"] = time.perf_counter() - t["t0"]
        return report

    return check


def _sampled(robot: Robot, obj: Shape, n_grasps: int, fingers: tuple[str, ...], candidates: int, seed: int,
             physics: Callable[..., Any] | None, solve_top: int | None, trials: int, settings: dict, t: dict,
             obstacles: tuple[Shape, ...] = ()) -> list[SynthesizedGrasp]:
    """``start="sampled"`` (:func:`synthesize_grasps`): the drafts wait in one pool (a heap, best
    first by their drafted quality) and are checked (:class:`SetCheck`; a hand on an arm: reached)
    as they come to its top: a checked set goes back with its checked quality, and is solved when
    it is on top again."""
    session = Solver(robot, trials=1, seed=seed, solver=settings)
    grasps: list[SynthesizedGrasp] = []
    tried = 0
    orientations, reachable = arm_palms(robot, seed)
    hand, cone = carried_hand(robot), session.solver_cfg.normal_cone_deg
    drafts = iter_contact_drafts(hand, obj, fingers, seed, cone_deg=cone, max_tries=TRIES_PER_SET * candidates,
                                 stats=t, orientations=orientations, reachable=reachable)
    check = SetCheck(hand, obj, fingers, cone_deg=cone, obstacles=obstacles, stats=t)
    pool: list[tuple[tuple, int, bool, ContactSet, GraspQuality]] = []  # (key, order, checked, set, quality)

    def top() -> tuple[ContactSet, GraspQuality] | None:
        """The pool's best checked set (left on top; None: the pool is empty), checking drafts as they surface."""
        while pool and not pool[0][2]:
            _, order, _, draft, _ = heapq.heappop(pool)
            found = check(draft)
            if found is not None:
                for s, q in reach_sets(robot, rank_sets([found], obj), fingers, seed + order, 1):
                    heapq.heappush(pool, (_rank_key(q), order, True, s, q))
        return (pool[0][3], pool[0][4]) if pool else None

    more, ahead, drawn = True, 0, 0
    while tried < candidates:
        t1 = time.perf_counter()
        best = top()
        while more and (best is None or (ahead < LOOK_AHEAD and not best[1].force_closure)):
            batch = next(drafts, None)
            if batch is None:
                more = False
                break
            ahead += 1
            t2 = time.perf_counter()
            for s, q in rank_sets(batch, obj):
                heapq.heappush(pool, (_rank_key(q), drawn, False, s, q))
                drawn += 1
            t["rank_s"] += time.perf_counter() - t2
            t1 += time.perf_counter() - t2  # generate_s: drawing and checking
            best = top()
        t["generate_s"] += time.perf_counter() - t1
        if best is None:
            break
        ahead = 0
        heapq.heappop(pool)
        s, q = best
        tried += 1
        problem = placeholder_problem(robot, obj, fingers, s.contacts, obstacles)
        t3 = time.perf_counter()
        result = session.solve(problem, start=s.posture, search=False)
        t["solve_s"] += time.perf_counter() - t3
        t["solved"] += 1
        seated = _seated(robot, obj, fingers, obstacles, problem, result, session, t) if result.success else None
        if seated is None:
            continue
        t["succeeded"] += 1
        g = SynthesizedGrasp(seated[0], s, q, seated[1], links=_pad_links(hand, fingers))
        grasps.append(g)
        _check(g, robot, physics, t)
        if (t["held"] if physics is not None else t["succeeded"]) >= n_grasps:
            return grasps
    return grasps


def _random(robot: Robot, obj: Shape, n_grasps: int, fingers: tuple[str, ...], candidates: int, seed: int,
            physics: Callable[..., Any] | None, solve_top: int | None, trials: int, settings: dict, t: dict,
            obstacles: tuple[Shape, ...] = ()) -> list[SynthesizedGrasp]:
    """``start="random"`` (:func:`synthesize_grasps`)."""
    t0 = time.perf_counter()
    cone = settings_of(robot, settings, None, None, None)[0].normal_cone_deg
    orientations, reachable = arm_palms(robot, seed)
    sets = pad_contact_sets(carried_hand(robot), obj, candidates, fingers, seed, cone_deg=cone, stats=t,
                            orientations=orientations, reachable=reachable, obstacles=obstacles)
    t1 = time.perf_counter()
    ranked = reach_sets(robot, rank_sets(sets, obj), fingers, seed, solve_top or 2 * n_grasps)
    problems = [placeholder_problem(robot, obj, fingers, s.contacts, obstacles) for s, _ in ranked]
    t2 = time.perf_counter()
    results = _solve(problems, trials, seed, settings)
    t.update(generate_s=t1 - t0, rank_s=t2 - t1, solve_s=time.perf_counter() - t2, solved=len(problems))
    links = _pad_links(carried_hand(robot), fingers)
    session = Solver(robot, trials=1, seed=seed, solver=settings)
    seated = [_seated(robot, obj, fingers, obstacles, p, r, session, t) if r.success else None
              for p, r in zip(problems, results, strict=True)]
    grasps = [SynthesizedGrasp(pr[0], s, q, pr[1], links=links) for pr, (s, q) in zip(seated, ranked, strict=True)
              if pr is not None]
    t["succeeded"] = len(grasps)
    for g in grasps:
        _check(g, robot, physics, t)
    return grasps


def _seated(robot: Robot, obj: Shape, fingers: tuple[str, ...], obstacles: tuple[Shape, ...], problem: GraspProblem,
            result: GraspResult, session: Solver, t: dict) -> tuple[GraspProblem, GraspResult] | None:
    """A solved grasp with its pads seated on the surface (:func:`seat_pads`), or None (counted in
    ``t["unseated"]``)."""
    seated = seat_pads(robot, carried_hand(robot), obj, problem, result,
                       lambda p, x: _evaluator(session).solve(p, start=x, search=False),
                       lambda c: placeholder_problem(robot, obj, fingers, c, obstacles))
    t["unseated"] += seated is None
    return seated


@functools.lru_cache(maxsize=4)
def _evaluator(session: Solver) -> Solver:
    """A solver of ``session``'s settings whose warm start is no step: its result is the start's
    posture, measured (errors, FCL check, pre-grasp and squeeze) as a solve's is."""
    polish = {**dataclasses.asdict(session.solver_cfg.polish), "iterations": 0}
    return Solver(session.robot, trials=1, seed=session.seed,
                  solver={**dataclasses.asdict(session.solver_cfg), "polish": polish})


def _solve(problems: list[GraspProblem], trials: int, seed: int, settings: dict) -> list[GraspResult]:
    """The problems solved as one batch, else one at a time where the batch is refused."""
    if not problems:
        return []
    try:
        return solve_many(problems, trials=trials, seed=seed, solver=settings)
    except ProblemError:
        return [solve(p, trials=trials, seed=seed, solver=settings) for p in problems]


def _pairs(robot: Robot, obj: Shape, n_grasps: int, fingers: tuple[str, ...], candidates: int, seed: int,
           physics: Callable[..., Any] | None, solve_top: int | None, trials: int, settings: dict, t: dict,
           obstacles: tuple[Shape, ...] = ()) -> list[SynthesizedGrasp]:
    """A gripper's grasps (:func:`synthesize_grasps`): antipodal pairs, the best solved by the search."""
    t0 = time.perf_counter()
    width = jaw_width(robot)
    pairs = antipodal_pairs(obj, width, candidates, seed)
    t1 = time.perf_counter()
    t.update(tried=SAMPLES_OF_PAIRS, pairs=len(pairs), width_mm=width * 1000)
    chosen = pairs[: solve_top or 2 * n_grasps]
    problems = [_pair_problem(robot, obj, p, obstacles) for p in chosen]
    results = _solve(problems, trials, seed, settings)
    t.update(generate_s=t1 - t0, solve_s=time.perf_counter() - t1, solved=len(problems))
    grasps = []
    for problem, pair, result in zip(problems, chosen, results, strict=True):
        if result.success:
            q = grasp_quality(pair.points, pair.normals, np.asarray(obj.pose[:3], dtype=np.float64), FRICTION)
            candidate = ContactSet(tuple(robot.cfg.gripper_points), pair.points, pair.normals,
                                   trial_posture(robot, result.best), pair.angles_deg)
            grasps.append(SynthesizedGrasp(problem, candidate, GraspQuality(float(q.epsilon), float(
                q.min_singular_value), bool(q.force_closure)), result))
    t["succeeded"] = len(grasps)
    return grasps


def _pair_problem(robot: Robot, obj: Shape, pair: PointPair, obstacles: tuple[Shape, ...]) -> GraspProblem:
    """The gripper's problem of a pair: its points in the object frame, the obstacles."""
    T = pose_to_matrix_np(obj.pose)
    local = (pair.points - T[:3, 3]) @ T[:3, :3]
    data = {"robot": robot.cfg.name, "object": obj.to_mapping(), "points": local.tolist(),
            "obstacles": [o.to_mapping() for o in obstacles]}
    return GraspProblem.from_mapping(data, robot_cfg=robot.cfg, allow_outside_paths=True)
