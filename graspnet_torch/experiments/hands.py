"""Many hands, everyday objects (beyond the paper): :func:`gt.synthesize_grasps` with its defaults
(each hand's own default fingers: its opposing finger and the two nearest) for the shipped hand,
TriFinger and every public hand of ``examples/`` on everyday objects at real scale
(:mod:`~graspnet_torch.experiments.household`: primitives at household sizes and pybullet_data
meshes, long ones among them), each object placed as the synthesis experiment places one.

Per hand and object (object k with seed ``seed`` + k, ``candidates`` contact sets at most, the
sampler drawing at most 50 palm poses per set asked for; a run still going after ``max_s`` seconds is
stopped and counted apart, since a hand that finds no touching palm pose can draw them for many
minutes): the top-1 grasp
checked in MuJoCo with the pinned protocol (:func:`gt.check_until_failure`: holds 6/6 pushes), as the
experiment ``synthesis`` checks it; each reported grasp's deepest link inside the object recomputed
(FCL, no link exempt) and, where a grasp says which links touch (``links``), the farthest of them
from the object (FCL distance). Per hand: the share of objects whose top-1 grasp holds 6/6, over all
and over the long ones; the grasps' types (a grasp's ``type``; one without it: precision); the
median and longest time per object; the objects missed, by cause: no grasp found (the reason,
summarized), found but the top-1 does not hold, or a reported grasp deeper than 1 mm; a picture of
its top grasp on one object. A hand whose URDF is not there (fetched: ``scripts/fetch_hands.py``;
in a Python package not installed) is reported as such and not run.

Targets (``checks``, issue 59): each hand's top-1 holds on at least 80 % of the objects; on the long
ones, at least 80 % for the shipped hand and for at least 3 public hands; no reported grasp deeper
than 1 mm, and no link a grasp says touches farther than 1 mm from the object.
"""

from __future__ import annotations

import importlib.util
import math
import re
import signal
import threading
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.errors import GraspnetError
from graspnet_torch.experiments.grasp_checks import (
    decompose_s,
    depth_mm,
    holds_text,
    link_gap_mm,
    map_jobs,
    robot_of,
)
from graspnet_torch.experiments.household import OBJECTS, Household, household_objects, object_names
from graspnet_torch.experiments.report import ExperimentReport, Figure
from graspnet_torch.paths import repo_root
from graspnet_torch.physics import check_until_failure
from graspnet_torch.robot.shape import Shape
from graspnet_torch.settings import setting
from graspnet_torch.synthesis.synthesize import no_grasp_reason
from graspnet_torch.table import markdown_table
from graspnet_torch.viz import Panel, render_robot
from graspnet_torch.viz.result import posture_panels

__all__ = ["HANDS", "HandsCfg", "hand_status", "run_hands", "summarize_hand"]

HANDS = {  # name -> robot config (a shipped robot's name or a YAML path under the repository)
    "hand": "hand", "trifinger": "examples/trifinger/trifinger.yaml",
    "allegro": "examples/allegro_hand/allegro_hand_right.yaml", "leap": "examples/leap_hand/leap_hand_right.yaml",
    "barrett": "examples/barrett_hand/barrett_hand.yaml", "dclaw": "examples/dclaw_gripper/dclaw_gripper.yaml",
    "shadow": "examples/shadow_hand/shadow_hand_right.yaml", "dexmate": "examples/dexmate_f5d6/dexmate_f5d6_right.yaml",
    "schunk": "examples/schunk_svh/schunk_svh_right.yaml", "ability": "examples/ability_hand/ability_hand_right.yaml",
    "inspire": "examples/inspire_hand/inspire_hand_right.yaml", "icub": "examples/icub_hand/icub_hand_left.yaml"}
SHIPPED = "hand"
NOT_PUBLIC_HANDS = (SHIPPED, "trifinger")  # counted apart from the public dexterous hands
CAPPED = "stopped at the"  # a run past max_s: its reason starts so
TOP1_PCT, LONG_PCT, LONG_HANDS, DEPTH_MM, GAP_MM = 80.0, 80.0, 3, 1.0, 1.0  # the targets
PUBLIC_HANDS = 8  # public dexterous hands (not the shipped hand, not TriFinger) at TOP1_PCT or more


@dataclass(frozen=True)
class HandsCfg:
    """``+experiment=hands``."""

    hands: tuple[str, ...] = setting(tuple(HANDS))  # names of HANDS, or robot configs (a name or a YAML path)
    objects: int | tuple[str, ...] = setting(len(OBJECTS), lo=1, hi=len(OBJECTS), choices=object_names())  # n
    # spread over the household table, or names
    candidates: int = setting(64, lo=1, hi=100_000)  # contact sets solved at most per object (50 palm poses each)
    max_s: float = setting(120.0, lo=0.0, hi=86_400.0)  # a hand-object run is stopped after this (0: never)
    grasps: int = setting(1, lo=1, hi=100)  # grasps reported per object (the top-1 is the one counted)
    seed: int = setting(2026, lo=0, hi=2**31 - 1)  # object k is synthesized with seed + k
    physics: bool = True  # the MuJoCo check (without it nothing counts as holding)
    jobs: int = setting(2, lo=1, hi=256)  # processes over the objects (one torch thread each)


def _config(hand: str) -> str:
    return HANDS.get(hand, hand)


def hand_status(hand: str) -> str | None:
    """Why a hand cannot run here (its URDF not fetched; its Python package not installed), else None."""
    config = _config(hand)
    if not config.endswith(".yaml"):
        return None
    path = repo_root() / config
    if not path.is_file():
        return f"no config {config}"
    urdf = str((yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get("urdf", ""))
    if urdf.startswith("package://"):
        package = urdf.removeprefix("package://").split("/", 1)[0]
        found = importlib.util.find_spec(package) is not None
        return None if found else f"not installed: Python package {package} (the config says how)"
    return None if (path.parent / urdf).is_file() else "not fetched: run scripts/fetch_hands.py"


class _OverTime(BaseException):
    """A run past its time cap (a BaseException: no ``except Exception`` inside the run swallows it)."""


@contextmanager
def _time_cap(seconds: float) -> Iterator[None]:
    """Raise :class:`_OverTime` in this thread once ``seconds`` of wall time have passed (SIGALRM;
    no cap where there is no such signal or off the main thread, and for 0)."""
    if seconds <= 0 or not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread():
        yield
        return

    def expire(signum, frame):
        raise _OverTime

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _one(hand: str, obj: Shape, cfg: HandsCfg, seed: int) -> dict:
    """One hand on one object (in a worker process where ``cfg.jobs`` > 1; one torch thread)."""
    torch.set_num_threads(1)
    robot, stats, t0 = robot_of(_config(hand)), {}, time.perf_counter()
    try:
        with _time_cap(cfg.max_s):
            grasps = gt.synthesize_grasps(robot, obj, n_grasps=cfg.grasps, candidates=cfg.candidates, seed=seed,
                                          physics=check_until_failure if cfg.physics else None, stats=stats)
        reason = "" if grasps else no_grasp_reason(stats)
    except GraspnetError as exc:  # a hand the synthesis refuses (pads that cannot oppose): said in one line
        grasps, reason = [], f"refused: {exc}"
    except _OverTime:  # what it had found is lost with the call: counted apart
        grasps, reason = [], f"{CAPPED} {cfg.max_s:g} s cap"
    wall = time.perf_counter() - t0
    links = [tuple(getattr(g, "links", ()) or ()) for g in grasps]
    return {"grasps": grasps, "holds": [g.holds for g in grasps], "wall": wall, "reason": reason,
            "types": [getattr(g, "type", None) or "precision" for g in grasps],
            "depth_mm": [depth_mm(robot, g) for g in grasps],
            "gap_mm": [link_gap_mm(robot, g, ls) for g, ls in zip(grasps, links, strict=True) if ls]}


def _held(row: dict) -> bool:
    return bool(row["holds"]) and row["holds"][0] == 6


def _reason_key(reason: str) -> str:
    """A no-grasp reason without its counts, to group the objects that share it."""
    return reason if reason.startswith(CAPPED) else re.sub(r"\d+(\.\d+)?", "N", reason.removeprefix("no grasp found: "))


def summarize_hand(rows: list[dict], long: list[bool]) -> dict:
    """A hand's numbers over its objects (module docstring) from its per-object rows; ``long``: which
    objects are long."""
    n, n_long = len(rows), sum(long)
    held = [_held(r) for r in rows]
    walls = [r["wall"] for r in rows]
    deep = [max(r["depth_mm"], default=0.0) > DEPTH_MM for r in rows]
    reasons = Counter(_reason_key(r["reason"]) for r in rows if not r["holds"])
    return {"objects": n, "top-1 holds %": 100 * sum(held) / n if n else 0.0,
            "long objects": n_long,
            "long top-1 holds %": 100 * sum(h for h, lg in zip(held, long, strict=True) if lg) / n_long
            if n_long else math.nan,
            "types": Counter(t for r in rows for t in r["types"]),
            "median s": float(np.median(walls)) if walls else 0.0, "max s": max(walls, default=0.0),
            "capped": sum(r["reason"].startswith(CAPPED) for r in rows),
            "no grasp": sum(not r["holds"] and not r["reason"].startswith(CAPPED) for r in rows),
            "does not hold": sum(bool(r["holds"]) and not h for r, h in zip(rows, held, strict=True)),
            "deeper": sum(deep), "deepest mm": max((d for r in rows for d in r["depth_mm"]), default=0.0),
            "farthest contact link mm": max((d for r in rows for d in r["gap_mm"]), default=math.nan),
            "reasons": reasons}


def _pct(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.0f}"


def _row(hand: str, s: dict) -> list[str]:
    types = ", ".join(f"{k} {v}" for k, v in sorted(s["types"].items())) or "-"
    gap = s["farthest contact link mm"]
    return [hand, str(s["objects"]), _pct(s["top-1 holds %"]), f"{_pct(s['long top-1 holds %'])} "
            f"(of {s['long objects']})", types, f"{s['median s']:.1f}", f"{s['max s']:.1f}", str(s["capped"]),
            str(s["no grasp"]), str(s["does not hold"]), str(s["deeper"]), f"{s['deepest mm']:.2f}",
            "-" if math.isnan(gap) else f"{gap:.2f}"]


CHECKED = "checked in MuJoCo, the pinned protocol (6 pushes; a grasp is pushed until one fails)"
NOT_CHECKED = "NOT checked (physics off: nothing counts as holding)"
HEADERS = ["hand", "objects", "top-1 holds 6/6 %", "long objects: top-1 holds %", "grasp types", "median s per object",
           "max s per object", "stopped at the time cap", "no grasp found", "found, top-1 does not hold",
           "deeper than 1 mm", "deepest mm", "farthest contact link mm"]


def _hand_rows(hand: str, objs: list[tuple[Household, Shape]], cfg: HandsCfg) -> list[dict]:
    args = [(hand, shape, cfg, cfg.seed + k) for k, (_, shape) in enumerate(objs)]
    return map_jobs(_one, args, cfg.jobs, f"hands: {hand}")


def run_hands(cfg: HandsCfg, out: Path) -> ExperimentReport:
    """The sections of the module docstring, the issue's targets as ``checks`` and a picture per hand."""
    objs = household_objects(cfg.objects)
    prepared = map_jobs(decompose_s, [(shape,) for _, shape in objs], cfg.jobs)  # before the timed runs, cached
    long = [o.long for o, _ in objs]
    results, summaries, missing, figures, numbers, timings = {}, {}, {}, [], {}, {}
    for hand in cfg.hands:
        status = hand_status(hand)
        if status is not None:
            missing[hand] = status
            continue
        results[hand] = _hand_rows(hand, objs, cfg)
        s = summaries[hand] = summarize_hand(results[hand], long)
        for key in ("top-1 holds %", "long top-1 holds %", "capped", "no grasp", "does not hold", "deeper",
                    "deepest mm", "farthest contact link mm"):
            if not math.isnan(s[key]):  # no long object, no grasp that says which links touch: no number
                numbers[f"{hand}/{key}"] = float(s[key])
        timings[f"{hand}/median s"], timings[f"{hand}/max s"] = s["median s"], s["max s"]
        figures.append(_picture(hand, results[hand], objs, out))
    timings["decomposition max s"] = max(prepared, default=0.0)
    rows = [_row(hand, summaries[hand]) if hand in summaries else [hand, missing[hand], *["-"] * 11]
            for hand in cfg.hands]
    body = "\n\n".join([_intro(cfg, objs, prepared), markdown_table(HEADERS, rows), _reasons(summaries),
                        _grid(results, objs)])
    return ExperimentReport("hands", "Many hands, everyday objects: grasp synthesis across public hands", body,
                            figures=figures, numbers=numbers, timings=timings,
                            checks=_checks(summaries, missing, cfg, any(long)), results=results)


def _intro(cfg: HandsCfg, objs: list[tuple[Household, Shape]], prepared: list[float]) -> str:
    n_long = sum(o.long for o, _ in objs)
    return (f"**Many hands, everyday objects.** {len(objs)} everyday objects at real scale "
            f"(`graspnet_torch/experiments/household.py`: primitives at household sizes, ellipsoids and capsules as "
            f"meshes, pybullet_data meshes scaled to size; {n_long} long: at least 120 mm long, at most 60 mm across), "
            f"each with its bounding box centred 0.2 m above the origin: {', '.join(o.name for o, _ in objs)}. "
            f"`gt.synthesize_grasps` with its defaults (each hand's own default fingers), object k with seed "
            f"{cfg.seed} + k, at most {cfg.candidates} contact sets solved per object, a run stopped after "
            f"{cfg.max_s:g} s (what it had found lost: counted apart; 0: never), the top {cfg.grasps} reported; "
            f"the top-1 grasp {CHECKED if cfg.physics else NOT_CHECKED}. "
            "Deepest: recomputed here, the deepest link of any reported grasp inside the object (FCL, no link "
            "exempt); farthest contact link: of the links a grasp says touch (where it says so), the farthest from "
            "the object (FCL distance). Types: each grasp's `type` (none: precision). Time per object: the "
            f"call's wall time, {cfg.jobs} process{'es' if cfg.jobs > 1 else ''} over the objects, one torch thread "
            "each. Not timed: each mesh object's convex decomposition (cached on disk), made before the "
            f"runs: longest {max(prepared, default=0.0):.1f} s here (0 where cached).")


def _reasons(summaries: dict) -> str:
    """Why each hand found no grasp where it found none: the reasons without their counts, grouped."""
    lines = ["Objects with no grasp, by reason:", ""]
    for hand, s in summaries.items():
        for reason, count in s["reasons"].most_common():
            lines.append(f"- {hand}: {count} x {reason}")
    return "\n".join(lines) if len(lines) > 2 else "Every hand run found a grasp on every object."


def _grid(results: dict, objs: list[tuple[Household, Shape]]) -> str:
    """Object by hand: the pushes the top-1 grasp held (of 6; none: no grasp found)."""
    hands = list(results)
    rows = [[o.name + (" (long)" if o.long else ""),
             *[str(results[h][k]["holds"][0]) if results[h][k]["holds"] else "none" for h in hands]]
            for k, (o, _) in enumerate(objs)]
    return "Pushes the top-1 grasp held, of 6 (none: no grasp found):\n\n" + markdown_table(["object", *hands], rows)


def _checks(summaries: dict, missing: dict, cfg: HandsCfg, any_long: bool) -> list[tuple[str, bool]]:
    """The issue's targets; a hand not run misses its own."""
    checks = [(f"{hand}: top-1 grasp holds 6/6 on >= {TOP1_PCT:g} % of the objects: {why}", False)
              for hand, why in missing.items()]
    for hand, s in summaries.items():
        checks.append((f"{hand}: top-1 grasp holds 6/6 on {s['top-1 holds %']:.0f} % of the objects >= {TOP1_PCT:g} %",
                       s["top-1 holds %"] >= TOP1_PCT))
    public = [h for h, s in summaries.items() if h not in NOT_PUBLIC_HANDS and s["top-1 holds %"] >= TOP1_PCT]
    checks.append((f"public dexterous hands whose top-1 holds on >= {TOP1_PCT:g} % of the objects: {len(public)} "
                   f"({', '.join(public) or 'none'}) >= {PUBLIC_HANDS}", len(public) >= PUBLIC_HANDS))
    if not any_long:
        checks.append(("long objects: none in this run (`objects` leaves them out)", False))
    else:
        s = summaries.get(SHIPPED)
        checks.append((f"{SHIPPED} (shipped): top-1 holds on {_pct(s['long top-1 holds %'])} % of the long objects "
                       f">= {LONG_PCT:g} %", s["long top-1 holds %"] >= LONG_PCT) if s else
                      (f"{SHIPPED} (shipped) on the long objects: not run", False))
        good = [h for h, s in summaries.items() if h != SHIPPED and s["long top-1 holds %"] >= LONG_PCT]
        checks.append((f"public hands whose top-1 holds on >= {LONG_PCT:g} % of the long objects: {len(good)} "
                       f"({', '.join(good) or 'none'}) >= {LONG_HANDS}", len(good) >= LONG_HANDS))
    deepest = max((s["deepest mm"] for s in summaries.values()), default=0.0)
    checks.append((f"every reported grasp (every hand) at most {DEPTH_MM:g} mm deep: deepest {deepest:.2f} mm",
                   deepest <= DEPTH_MM and bool(summaries)))
    gaps = [s["farthest contact link mm"] for s in summaries.values() if not math.isnan(s["farthest contact link mm"])]
    farthest = max(gaps, default=0.0)
    checks.append((f"every link a reported grasp says touches (every hand) within {GAP_MM:g} mm of the object: "
                   f"farthest {farthest:.2f} mm", farthest <= GAP_MM and bool(gaps)))
    return checks


def _picture(hand: str, rows: list[dict], objs: list[tuple[Household, Shape]], out: Path) -> Figure:
    """A hand's top grasp on one object: the first whose top-1 holds, else the first with a grasp."""
    robot = robot_of(_config(hand))
    order = sorted(range(len(rows)), key=lambda k: (not _held(rows[k]), not rows[k]["grasps"]))
    k = order[0]
    name = objs[k][0].name
    file = f"hands_{re.sub(r'[^A-Za-z0-9_]+', '_', hand)}.png"
    if rows[k]["grasps"]:
        grasp = rows[k]["grasps"][0]
        panel = posture_panels(robot, grasp.problem, grasp.result)[0]
        panels, what = [replace(panel, caption=f"{hand}, {name}: {holds_text(grasp)}")], holds_text(grasp)
    else:
        panels, what = [Panel(f"{hand}, {name}: no grasp", robot.home_posture(), meshes=(objs[k][1].trimesh(),))], \
            "no grasp found on any object"
    render_robot(robot, panels, out / file)
    return Figure(file, f"{hand}: its top grasp on {name} ({what}; contacts red; colliding links red).")
