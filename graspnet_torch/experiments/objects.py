"""Your own object, anywhere (beyond the paper): the shipped hand tasks moved and turned, as primitives
and as meshes, and contact sets on real object meshes, with every solver on the same problems.

Sections:

1. **Moved tasks**: glass3, glass4 and videotape5 with the object (and so its contacts) moved by
   ``poses`` random rigid motions (anywhere within ``radius`` of the origin, any orientation:
   :func:`~graspnet_torch.tasks.objects.random_pose`), no palm bounds given (the search space
   follows the contacts), the object as its primitive and as the same object written as a mesh
   (:func:`~graspnet_torch.tasks.objects.as_mesh`); pose k is solved with seed k.
2. **Real meshes**: ``sets`` contact sets on each of ``objects`` (real object meshes of
   ``pybullet_data``, :data:`~graspnet_torch.tasks.objects.REAL_OBJECTS`), each object at a random
   pose, each set from a collision-free posture whose fingertips touch the mesh
   (:func:`~graspnet_torch.collision.problems.closure_problem`): a grasp is known to exist.

Every problem is solved by each of ``solvers`` with its defaults in the paper's point contact model
(``solver.contact_model=point``: the tip frames on the contacts; the surface model, pads on the
surface, is the experiment ``contact``'s) (``trials`` trials): success is the
result's (every contact finger within 1 mm, collision-free by FCL), the wall time a whole
``gt.solve`` call (median per problem). Targets (``checks``): the default solver succeeds on at
least 95 % of each moved task, primitive and mesh, and on at least 90 % of the real-mesh sets.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import graspnet_torch as gt
from graspnet_torch.collision.problems import real_mesh_problems as closed_on_real_meshes
from graspnet_torch.experiments.report import ExperimentReport, Figure, progress, require
from graspnet_torch.settings import setting
from graspnet_torch.solver.api import robot_and_ik
from graspnet_torch.solver.config import DEFAULT_TRIALS
from graspnet_torch.table import markdown_table
from graspnet_torch.tasks.objects import REAL_OBJECTS, as_mesh, random_pose
from graspnet_torch.viz import render_robot
from graspnet_torch.viz.result import posture_panels

__all__ = ["ObjectsCfg", "run_objects"]

TASKS = ("glass3", "glass4", "videotape5")
POINT = {"contact_model": "point"}  # the contacts' sets are fingertip contacts: the paper's point model
SOLVERS = {"srv": POINT, "dls": {**POINT, "method": "dls", "max_iterations": 100},
           "cmaes": {**POINT, "method": "cmaes"}}
MOVED_PCT = 95.0
REAL_PCT = 90.0


@dataclass(frozen=True)
class ObjectsCfg:
    """``+experiment=objects``."""

    poses: int = setting(50, lo=1, hi=100_000)  # random poses per task
    radius: float = setting(0.3, lo=0.0, hi=10.0)  # m: the object's poses lie within this of the origin
    tasks: tuple[str, ...] = setting(TASKS, choices=TASKS)
    sets: int = setting(2, lo=1, hi=1000)  # contact sets per real object
    objects: tuple[str, ...] = setting(tuple(REAL_OBJECTS), choices=tuple(REAL_OBJECTS))
    fingers: int = setting(3, lo=2, hi=5)  # contacts per real-mesh set
    solvers: tuple[str, ...] = setting(tuple(SOLVERS), choices=tuple(SOLVERS))
    trials: int = setting(DEFAULT_TRIALS, lo=1, hi=10_000)  # gt.solve's
    seed: int = setting(0, lo=0, hi=2**31 - 1)

    def __post_init__(self) -> None:
        require("srv" in self.solvers, "experiments.objects.solvers: the default solver (srv) must be among them")


def moved_problems(cfg: ObjectsCfg, folder: Path) -> dict[tuple[str, str], list]:
    """(task, 'primitive' | 'mesh') -> the task moved to ``cfg.poses`` random poses (no bounds)."""
    out = {}
    for task in cfg.tasks:
        base = gt.GraspProblem.from_task(task)
        rng = np.random.default_rng(cfg.seed)
        moved = [base.moved(random_pose(rng, cfg.radius)) for _ in range(cfg.poses)]
        out[task, "primitive"] = moved
        out[task, "mesh"] = [as_mesh(p, folder) for p in moved]
    return out


def real_mesh_problems(cfg: ObjectsCfg) -> list:
    """``cfg.sets`` closure contact sets on each real object, each object at a random pose
    (:func:`~graspnet_torch.collision.problems.real_mesh_problems`)."""
    return closed_on_real_meshes(gt.load_robot("hand"), cfg.objects, np.random.default_rng(cfg.seed), cfg.sets,
                                 cfg.radius, cfg.fingers, cfg.seed)


def _solve_all(problems: list, solver: str, cfg: ObjectsCfg, desc: str) -> dict:
    """Success, wall time and best error of each problem under one solver."""
    ok, wall, err, reasons = [], [], [], []
    for k, problem in enumerate(progress(problems, desc=desc, unit="problem")):
        t0 = time.perf_counter()
        result = gt.solve(problem, trials=cfg.trials, seed=cfg.seed + k, solver=SOLVERS[solver])
        wall.append(time.perf_counter() - t0)
        ok.append(result.success)
        err.append(result.best.total_error_mm)
        reasons.append(result.failure)
    return {"ok": ok, "wall": wall, "error": err, "failures": reasons}


def _row(label: list[str], r: dict) -> list[str]:
    n = len(r["ok"])
    failures = {}
    for reason in r["failures"]:
        if reason:
            kind = reason.split(":")[0]
            failures[kind] = failures.get(kind, 0) + 1
    why = ", ".join(f"{v} {k}" for k, v in sorted(failures.items())) or "-"
    return [*label, f"{sum(r['ok'])}/{n}", f"{100 * np.mean(r['ok']):.0f}", f"{np.median(r['wall']):.2f}", why]


def _measure(problems: list, label: list[str], target: float, what: str, cfg: ObjectsCfg, numbers: dict,
             timings: dict, checks: list) -> list[list[str]]:
    """Every solver on the same problems: a table row each, its numbers, and the default's check."""
    rows = []
    for solver in cfg.solvers:
        r = _solve_all(problems, solver, cfg, f"objects: {' '.join(label)} {solver}")
        rows.append(_row([*label, solver], r))
        pct = 100 * float(np.mean(r["ok"]))
        key = "/".join(label[:1] if label[0] == "real meshes" else label)
        numbers[f"{key}/{solver}/success %"] = pct
        timings[f"{key}/{solver}/median wall s"] = float(np.median(r["wall"]))
        if solver == "srv":
            checks.append((f"default solver, {what}: {pct:.0f} % succeed >= {target:g} %", pct >= target))
    return rows


def run_objects(cfg: ObjectsCfg, out: Path) -> ExperimentReport:
    """Both sections (see the module's docstring), with the targets as ``checks`` and a picture of
    the default solver's grasp on the first real-mesh set."""
    numbers, timings, rows, checks = {}, {}, [], []
    with tempfile.TemporaryDirectory(prefix="graspnet_objects_") as tmp:
        for (task, kind), problems in moved_problems(cfg, Path(tmp)).items():
            rows += _measure(problems, [task, kind], MOVED_PCT, f"{task} as a {kind} at {cfg.poses} random poses",
                             cfg, numbers, timings, checks)
        real = real_mesh_problems(cfg)
        rows += _measure(real, ["real meshes", f"{len(cfg.objects)} objects"], REAL_PCT,
                         f"{len(real)} contact sets on real meshes", cfg, numbers, timings, checks)
        figures = [_picture(real[0], out)]
    headers = ["problems", "object", "solver", "succeeded", "%", "median wall s", "failures (why)"]
    body = (f"**Objects anywhere.** Each shipped hand task with its object moved and turned to {cfg.poses} random "
            f"poses (within {cfg.radius:g} m of the origin, any orientation; no palm bounds: the search space "
            f"follows the contacts), as its primitive and as the same object written as a mesh (STL); then "
            f"{cfg.sets} contact set(s) of {cfg.fingers} fingers on each of {len(cfg.objects)} real object meshes "
            f"({', '.join(cfg.objects)}; `pybullet_data`), each from a collision-free posture whose fingertips "
            f"touch the mesh. Every solver with its defaults, {cfg.trials} trials, problem k with seed "
            f"{cfg.seed} + k. Success: every contact finger within 1 mm and no collision (FCL).\n\n"
            + markdown_table(headers, rows))
    return ExperimentReport("objects", "Your own object, anywhere: moved tasks and real meshes", body,
                            figures=figures, tables=["Objects"], numbers=numbers, timings=timings, checks=checks)


def _picture(problem, out: Path) -> Figure:
    """The default solver's grasp of a real-mesh contact set, two views."""
    robot, _ = robot_and_ik(problem.robot_cfg)
    result = gt.solve(problem, trials=DEFAULT_TRIALS, seed=0, solver=POINT)
    render_robot(robot, posture_panels(robot, problem, result), out / "objects_real_mesh.png")
    return Figure("objects_real_mesh.png", f"The default solver's grasp of contact set '{problem.name}' (a real mesh "
                                           f"at a random pose): {result.best.total_error_mm:.3g} mm, "
                                           f"{result.best.collisions} collision(s).")
