"""An object in, grasps out (beyond the paper): the contact-based grasp synthesis
(:func:`gt.synthesize_grasps`: pad contact sets ranked by grasp quality, solved in the surface
contact model) beside the planner with no contact reasoning (:func:`gt.baseline_grasps`: random palm
poses, every finger closed until it touches), on the same objects in the same run, every grasp
checked in MuJoCo (:func:`gt.check_until_failure`, the pinned protocol: 6/6 pushes; a grasp is pushed until
one fails).

Objects: ``objects`` of pybullet's procedurally generated objects (``pybullet_data/random_urdfs/
NNN/NNN.obj``, 1000 of them, scaled as their URDFs scale them: ``SCALE``), drawn without replacement
by ``seed`` from those used nowhere for tuning or tests (``EXCLUDED``: 000-003 are
:data:`~graspnet_torch.tasks.objects.REAL_OBJECTS`, 010-012 tuned the synthesis, 626, 686, 898 and 942 tuned
TriFinger's pad and squeeze, 168 is empty), each with its
bounding box centred 0.2 m above the origin (as the synthesis job places an object:
:func:`~graspnet_torch.tasks.objects.centred_mesh`); object k is synthesized with seed ``seed`` +
k. Robots: the shipped hand (thumb, index, middle), TriFinger by config
(``examples/trifinger/trifinger.yaml``, its three fingers, its config's pads and solver defaults)
and the hand on the arm (``arm_hand``: the same fingers; each object moved to ``ARM_CENTRE``, in
front of the shoulder, where the arm reaches it; no target of its own).

Per robot and method, over the objects: the share whose top-1 grasp holds 6/6, the share with any of
the top ``grasps`` holding 6/6, the median best Ferrari-Canny epsilon (synthesis: the best reported
grasp's ``quality.epsilon``, over the objects with a grasp), the deepest any link of any reported
grasp lies inside the object (recomputed here: FCL, no link exempt, as ``contact``'s), the verified
grasps per second (reported grasps holding 6/6 over the wall time of the whole set, ``jobs`` processes
over the objects: sampling, solving and physics) and the median time from the call's start to the
first physics check that holds 6/6 (an object with none: never, so the median is "never" where half the
objects have none); the share of the time spent in the physics checks, the rate the verified grasps
would reach were sampling and solving free (the ceiling that checking every landed grasp under the
pinned protocol puts on the run), and the rate were every check one that holds (the checks that held
6/6 alone, at the run's parallelism: the protocol's own ceiling on this machine, whatever the search;
a holding check simulates 0.5 s of settling and six 2 s pushes at 4 ms steps). Each object's convex
decomposition (the solver's collision proxy and the physics check need it; once per object,
cached on disk) is made before the timed runs and reported apart, as grasp synthesis benchmarks
report their object preprocessing.
Targets (``checks``, roadmap 18 and 20): the hand's top-1 holds on at least 80 % of the objects, at least
5 verified grasps/s, a median time to the first verified grasp of at most 2 s, the hand by config's
top-1 holds on at least 60 %, and no reported grasp deeper than 1 mm.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.experiments.grasp_checks import decompose_s, depth_mm, holds_text, map_jobs, robot_of
from graspnet_torch.experiments.report import ExperimentReport, Figure
from graspnet_torch.physics import check_until_failure
from graspnet_torch.robot.shape import Shape
from graspnet_torch.settings import setting
from graspnet_torch.synthesis.synthesize import START
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.objects import OBJECT_CENTRE, centred_mesh
from graspnet_torch.viz import Panel, render_robot
from graspnet_torch.viz.result import posture_panels

__all__ = ["EXCLUDED", "ROBOTS", "SCALE", "SynthesisExperimentCfg", "fresh_objects", "object_mesh", "object_pool",
           "pick_objects", "run_synthesis"]

ROBOTS = {"hand": ("hand", ("thumb", "index", "middle")),  # name -> (robot config, fingers)
          "trifinger": ("examples/trifinger/trifinger.yaml", ("f0", "f120", "f240")),
          "arm_hand": ("arm_hand", ("thumb", "index", "middle"))}
ARM_CENTRE = (0.4, -0.15, -0.25)  # arm_hand's objects: task env1's glass place, in front of the shoulder (m)
METHODS = ("synthesis", "baseline")
SCALE = 0.015  # random_urdfs/NNN/NNN.urdf: <mesh filename="NNN.obj" scale="0.015 0.015 0.015"/>
EXCLUDED = frozenset({0, 1, 2, 3, 10, 11, 12, 168, 626, 686, 898, 942})  # used for tuning or tests (module
# docstring); 168: its .obj has no faces (the one of the 1000 that trimesh reads empty)
TOP1_PCT = {"hand": 80.0, "trifinger": 60.0}  # the targets (none for the arm)
NO_BASELINE = ("The baseline runs beside the shipped hand only: on TriFinger (a holder with no palm box for it to "
               "face the object with) none of 128 palm poses touched the object on two of the random objects, at "
               "70 s per object.")
RATE, FIRST_S, DEPTH_MM = 5.0, 2.0, 1.0  # roadmap 20: 5 verified grasps/s (replacing 10/s)


@dataclass(frozen=True)
class SynthesisExperimentCfg:
    """``+experiment=synthesis``."""

    objects: int = setting(100, lo=1, hi=988)  # pybullet random objects, drawn by `seed` (EXCLUDED never)
    seed: int = setting(2026, lo=0, hi=2**31 - 1)  # draws the objects; object k is synthesized with seed + k
    candidates: int = setting(64, lo=1, hi=100_000)  # contact sets (synthesis) and palm poses (baseline) per object
    grasps: int = setting(5, lo=1, hi=100)  # grasps reported per object
    robots: tuple[str, ...] = setting(("hand", "trifinger", "arm_hand"), choices=tuple(ROBOTS))
    baseline: tuple[str, ...] = setting(("hand",), choices=tuple(ROBOTS))  # the robots the planner with no contact
    # reasoning runs beside the synthesis on (TriFinger: NO_BASELINE)
    physics: bool = True  # the MuJoCo check of every grasp (without it nothing counts as holding)
    start: str = setting("sampled", choices=START)  # gt.synthesize_grasps' start
    jobs: int = setting(2, lo=1, hi=256)  # processes over the objects (one torch thread each)


def object_pool() -> list[int]:
    """The random objects' numbers that no tuning or test uses (module docstring)."""
    return [k for k in range(1000) if k not in EXCLUDED]


def _picked(n: int, seed: int, pool: list[int]) -> list[int]:
    if n > len(pool):
        raise ConfigError(f"experiments.synthesis.objects: {n} exceeds the {len(pool)} unused random objects")
    return sorted(np.random.default_rng(seed).choice(pool, size=n, replace=False).tolist())


def object_mesh(number: int) -> Shape:
    """Random object ``number`` (0-999) at ``SCALE``, its bounding box centred 0.2 m above the origin."""
    import pybullet_data

    return centred_mesh(Path(pybullet_data.getDataPath()) / "random_urdfs" / f"{number:03d}" / f"{number:03d}.obj",
                        SCALE)


def pick_objects(n: int, seed: int) -> list[tuple[str, Shape]]:
    """``n`` random objects drawn by ``seed`` (name ``blobNNN``, bounding box centred 0.2 m above the origin)."""
    return [(f"blob{k:03d}", object_mesh(k)) for k in _picked(n, seed, object_pool())]


def fresh_objects(n: int, seed: int) -> list[int]:
    """The numbers of ``n`` random objects drawn by ``seed`` from those that neither tuning, tests nor
    the experiment's own 100 (seed 2026) use: objects this package has never been measured on."""
    used = set(_picked(100, 2026, object_pool()))
    return _picked(n, seed, [k for k in object_pool() if k not in used])


def _robot(name: str) -> gt.Robot:
    return robot_of(ROBOTS[name][0])


def _one(name: str, obj: Shape, method: str, cfg: SynthesisExperimentCfg, seed: int) -> dict:
    """One method on one object (in a worker process where ``cfg.jobs`` > 1; one torch thread): its
    grasps, what is recomputed of them, the wall time and the time to the first physics check that
    holds 6/6."""
    torch.set_num_threads(1)
    robot, fingers = _robot(name), ROBOTS[name][1]
    if robot.has_body:  # a hand on an arm: the object where the arm reaches it
        obj = replace(obj, pose=np.concatenate([obj.pose[:3] + np.subtract(ARM_CENTRE, OBJECT_CENTRE), obj.pose[3:]]))
    t0, first = time.perf_counter(), [math.inf]

    def physics(problem, result, robot):
        report = check_until_failure(problem, result, robot=robot)
        if report.held_all and math.isinf(first[0]):
            first[0] = time.perf_counter() - t0
        return report

    check = physics if cfg.physics else None
    stats: dict = {}
    if method == "synthesis":
        grasps = gt.synthesize_grasps(robot, obj, n_grasps=cfg.grasps, fingers=fingers, candidates=cfg.candidates,
                                      seed=seed, physics=check, stats=stats, start=cfg.start)
    else:
        grasps = gt.baseline_grasps(robot, obj, n_grasps=cfg.grasps, candidates=cfg.candidates, seed=seed,
                                    physics=check, stats=stats)
    wall = time.perf_counter() - t0
    holds = [g.holds for g in grasps]
    return {"grasps": grasps, "holds": holds, "wall": wall, "first_s": first[0], "stats": stats,
            "depth_mm": [depth_mm(robot, g) for g in grasps],
            "epsilon": [float(g.quality.epsilon) for g in grasps] if method == "synthesis" else []}


def _run(name: str, method: str, objs: list[tuple[str, Shape]], cfg: SynthesisExperimentCfg
         ) -> tuple[list[dict], float]:
    """One method on every object, ``cfg.jobs`` processes (joblib): the per-object rows in order and
    the wall time of the whole set."""
    args = [(name, obj, method, cfg, cfg.seed + k) for k, (_, obj) in enumerate(objs)]
    t0 = time.perf_counter()
    rows = map_jobs(_one, args, cfg.jobs, f"synthesis: {name}, {method}")
    return rows, time.perf_counter() - t0


def summarize(rows: list[dict], wall: float | None = None) -> dict:
    """A method's numbers over its objects (module docstring) from its per-object rows; ``wall``:
    the whole set's wall time (None: the rows' own times added up, one process)."""
    n = len(rows)
    top1 = [bool(r["holds"]) and r["holds"][0] == 6 for r in rows]
    anyk = [any(h == 6 for h in r["holds"]) for r in rows]
    best = [max(r["epsilon"]) for r in rows if r["epsilon"]]
    busy = sum(r["wall"] for r in rows)
    wall = busy if wall is None else wall
    verified = sum(sum(h == 6 for h in r["holds"]) for r in rows)
    first = float(np.median([r["first_s"] for r in rows])) if rows else math.inf
    physics = sum(r.get("stats", {}).get("physics_s", 0.0) for r in rows)
    held = sum(r.get("stats", {}).get("held", 0) for r in rows)
    held_s = sum(r.get("stats", {}).get("held_physics_s", 0.0) for r in rows)
    return {"objects": n, "top-1 holds %": 100 * float(np.mean(top1)) if n else 0.0,
            "any holds %": 100 * float(np.mean(anyk)) if n else 0.0,
            "median best epsilon": float(np.median(best)) if best else math.nan,
            "with a grasp %": 100 * sum(bool(r["holds"]) for r in rows) / max(n, 1),
            "deepest mm": max((d for r in rows for d in r["depth_mm"]), default=0.0),
            "verified": verified, "wall s": wall, "verified per s": verified / wall if wall > 0 else 0.0,
            "median first s": first, "s per object": busy / max(n, 1),
            "physics %": 100 * physics / busy if busy else 0.0,
            # the rate were sampling and solving free: the physics checks' share of the busy time alone
            "physics-bound per s": verified / (physics * wall / busy) if physics > 0 else math.inf,
            # ... and were every check one that holds: the holding checks' time alone, at the same parallelism
            "holding-bound per s": held / (held_s * wall / busy) if held_s > 0 else math.inf}


def _rate(value: float) -> str:
    return "-" if math.isinf(value) else f"{value:.2f}"


def run_synthesis(cfg: SynthesisExperimentCfg, out: Path) -> ExperimentReport:
    """The sections of the module docstring, the issue's targets as ``checks`` and a picture of the
    best synthesized grasp of the first objects."""
    objs = pick_objects(cfg.objects, cfg.seed)
    prepared = map_jobs(decompose_s, [(obj,) for _, obj in objs], cfg.jobs)  # before the timed runs, cached on disk
    results, summaries, rows, numbers, timings, checks = {}, {}, [], {}, {}, []
    for name in cfg.robots:
        for method in METHODS if name in cfg.baseline else METHODS[:1]:
            per, wall = _run(name, method, objs, cfg)
            results[name, method] = per
            s = summaries[name, method] = summarize(per, wall)
            rows.append([name, method, str(s["objects"]), f"{s['with a grasp %']:.0f}", f"{s['top-1 holds %']:.0f}",
                         f"{s['any holds %']:.0f}",
                         "-" if math.isnan(s["median best epsilon"]) else f"{s['median best epsilon']:.4f}",
                         f"{s['deepest mm']:.2f}", f"{s['verified per s']:.2f}",
                         "never" if math.isinf(s["median first s"]) else f"{s['median first s']:.2f}",
                         f"{s['s per object']:.1f}", f"{s['physics %']:.0f}", _rate(s["physics-bound per s"]),
                         _rate(s["holding-bound per s"])])
            for key in ("top-1 holds %", "any holds %", "median best epsilon", "with a grasp %", "deepest mm",
                        "verified"):
                numbers[f"{name}/{method}/{key}"] = float(s[key])
            for key in ("verified per s", "median first s", "s per object", "physics %",
                        "physics-bound per s", "holding-bound per s"):  # never / unbounded: null (strict JSON)
                timings[f"{name}/{method}/{key}"] = None if math.isinf(s[key]) else float(s[key])
    timings["decomposition median s"], timings["decomposition max s"] = float(np.median(prepared)), max(prepared)
    _checks(summaries, cfg, checks)
    no_baseline = f" {NO_BASELINE}" if "trifinger" in cfg.robots and "trifinger" not in cfg.baseline else ""
    headers = ["robot", "method", "objects", "with a grasp %", "top-1 holds 6/6 %", f"any of top {cfg.grasps} holds %",
               "median best epsilon", "deepest mm", "verified grasps/s", "median s to first verified",
               "s per object", "physics % of time", "verified grasps/s, physics alone",
               "verified grasps/s, holding checks alone"]
    body = (f"**An object in, grasps out.** {cfg.objects} of pybullet's random objects (`random_urdfs`, scale "
            f"{SCALE:g} as their URDFs, bounding box centred 0.2 m above the origin), drawn with seed {cfg.seed} from "
            f"the {1000 - len(EXCLUDED)} that no tuning or test uses and are not empty "
            f"({', '.join(f'{k:03d}' for k in sorted(EXCLUDED))} left out): "
            f"{', '.join(n for n, _ in objs[:12])}{' ...' if len(objs) > 12 else ''}. Object k with seed "
            f"{cfg.seed} + k, {cfg.candidates} candidates (contact sets; the baseline's palm poses), the top "
            f"{cfg.grasps} grasps reported. Synthesis: `gt.synthesize_grasps` (pad contact sets ranked by "
            "Ferrari-Canny epsilon at friction 0.6, solved in the surface contact model); baseline: "
            "`gt.baseline_grasps` (random palm poses facing the object, every finger closed until it touches: no "
            "contact reasoning). Holding: MuJoCo, DexGraspBench's protocol (6 pushes), every grasp "
            f"{'checked' if cfg.physics else 'NOT checked (physics off: nothing counts as holding)'}. Depth: "
            "recomputed here, the deepest link of any reported grasp inside the object (FCL, no link exempt). "
            f"Verified grasps/s: reported grasps holding 6/6 over the wall time of the whole set ({cfg.jobs} "
            f"process{'es' if cfg.jobs > 1 else ''} over the objects, one torch thread each: sampling, solving, "
            "physics); first verified: from the call's start to the first physics check holding 6/6 "
            "(never on an object without one). Physics % of time: the share of the objects' time spent in the "
            "MuJoCo checks (every candidate that landed is checked; a failing one stops early); verified grasps/s, "
            "physics alone: the rate were sampling and solving free (the verified grasps over the checks' share of "
            "the wall time), the ceiling this run's checks put on its grasps; holding checks alone: the rate were "
            "every check one that holds 6/6 (the checks that held 6/6 over their share of the wall time), the "
            "ceiling the pinned protocol itself puts on this machine, whatever the search. "
            "Not timed: each object's convex decomposition (for the "
            "solver's collision proxy and MuJoCo; once per object, cached on disk), made before the runs: "
            f"median {np.median(prepared):.1f} s, longest {max(prepared):.1f} s here "
            f"(0 where cached).{no_baseline}\n\n"
            + markdown_table(headers, rows))
    return ExperimentReport("synthesis", "An object in, grasps out: contact-based synthesis against a baseline",
                            body, figures=[_picture(results, objs, cfg, out)], numbers=numbers, timings=timings,
                            checks=checks, results=results)


def _checks(summaries: dict, cfg: SynthesisExperimentCfg, checks: list) -> None:
    """The issue's targets on the synthesis, where its robots were run; depth on every method."""
    for name in (r for r in cfg.robots if r in TOP1_PCT):
        s = summaries[name, "synthesis"]
        target = TOP1_PCT[name]
        checks.append((f"{name}: top-1 grasp holds 6/6 on {s['top-1 holds %']:.0f} % of the objects >= {target:g} %",
                       s["top-1 holds %"] >= target))
    if "trifinger" not in cfg.robots:
        checks.append((f"trifinger (the hand by config): top-1 grasp holds 6/6 on >= {TOP1_PCT['trifinger']:g} % of "
                       "the objects: not run (`robots` leaves it out)", False))
    if "hand" in cfg.robots:
        s = summaries["hand", "synthesis"]
        checks.append((f"hand: {s['verified per s']:.2f} verified grasps/s >= {RATE:g} (the physics checks alone: "
                       f"{_rate(s['physics-bound per s'])}/s; every check one that holds: "
                       f"{_rate(s['holding-bound per s'])}/s)", s["verified per s"] >= RATE))
        first = "never" if math.isinf(s["median first s"]) else f"{s['median first s']:.2f} s"
        checks.append((f"hand: median time to the first verified grasp {first} <= {FIRST_S:g} s",
                       s["median first s"] <= FIRST_S))
    deepest = max(s["deepest mm"] for s in summaries.values())
    checks.append((f"every reported grasp (every robot and method) at most {DEPTH_MM:g} mm deep: deepest "
                   f"{deepest:.2f} mm", deepest <= DEPTH_MM))


def _picture(results: dict, objs: list, cfg: SynthesisExperimentCfg, out: Path) -> Figure:
    """The best synthesized grasp of up to three objects side by side (the first robot's)."""
    name = cfg.robots[0]
    robot = _robot(name)
    shown = [(label, r["grasps"][0]) for (label, _), r in zip(objs, results[name, "synthesis"], strict=True)
             if r["grasps"]][:3]
    panels = []
    for label, grasp in shown:
        panel = posture_panels(robot, grasp.problem, grasp.result)[0]
        panels.append(replace(panel, caption=f"{label}: {holds_text(grasp)}, epsilon {grasp.quality.epsilon:.4f}"))
    if not panels:  # no object got a grasp: the first object and the hand at home
        panels = [Panel(f"{objs[0][0]}: no grasp", robot.home_posture(), meshes=(objs[0][1].trimesh(),))]
    render_robot(robot, panels, out / "synthesis_grasps.png")
    return Figure("synthesis_grasps.png", f"{name}: the best synthesized grasp (top-1) of "
                  f"{', '.join(label for label, _ in shown) or 'no object'} (contacts red; colliding links red).")
