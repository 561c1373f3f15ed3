"""An object in, grasps out, for a folder of meshes: the job behind ``scripts/synthesize_grasps.py``.

Every check comes first (:func:`prepare_synthesize`: the settings, the meshes to read, the robot
and its fingers' pads, the output folder), then each object is placed in front of the hand (its
bounding box centred at ``centre``, default :data:`OBJECT_CENTRE`; a hand on an arm needs it given:
where the arm reaches), handed to :func:`gt.synthesize_grasps` and written
to ``<out>/<object stem>.json``; then ``<out>/summary.csv``, one row per object. An object whose
result file exists is skipped (the run resumes where it stopped); one whose mesh cannot be read,
or where no grasp is found, is recorded with a one-line reason. Every file is written atomically.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch

from graspnet_torch.errors import ConfigError, GraspnetError, ProblemError
from graspnet_torch.files import check_output_path
from graspnet_torch.io import atomic_write_text
from graspnet_torch.jobs.configs import MAX_SEED
from graspnet_torch.jobs.interrupt import stop_if_interrupted
from graspnet_torch.jobs.solve_grasp import job_settings, resolve_problem, warn_on_failure
from graspnet_torch.meshes import MESH_FORMATS
from graspnet_torch.physics import check_until_failure
from graspnet_torch.robot.config import RobotCfg, robot_cfg_from_setting
from graspnet_torch.robot.kinds import robot_kind
from graspnet_torch.robot.opposition import default_fingers
from graspnet_torch.robot.robot import Robot, load_robot
from graspnet_torch.robot.shape import MAX_SCALE, Shape, check_mesh
from graspnet_torch.settings import MAX_LENGTH_M, Free, build, clip, number_list, setting
from graspnet_torch.solver.api import finger_ik_for
from graspnet_torch.synthesis import synthesize_grasps
from graspnet_torch.synthesis.candidates import check_pad_fingers
from graspnet_torch.synthesis.reach import carried_hand
from graspnet_torch.synthesis.synthesize import START, no_grasp_reason
from graspnet_torch.table import format_table
from graspnet_torch.tasks.auto_contacts import contact_fingers
from graspnet_torch.tasks.objects import OBJECT_CENTRE, centred_mesh
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz.grasp_view import render_grasps

__all__ = ["COLUMNS", "OBJECT_CENTRE", "SynthesizeGraspsJobCfg", "find_meshes", "object_shape",
           "prepare_auto", "prepare_synthesize", "solve_auto_problem", "synthesize_objects"]

CANDIDATES_PER_GRASP = 16  # contacts: auto: contact sets drawn per grasp asked for (at least 64)
COLUMNS = ("object", "grasps", "top1_type", "best_holds", "top1_holds_all", "top5_any_holds_all", "best_epsilon",
           "deepest_penetration_mm", "seconds", "reason")


@dataclass(frozen=True)
class SynthesizeGraspsJobCfg:
    """``scripts/synthesize_grasps.py`` (configs/synthesize_grasps.yaml)."""

    objects: str | None = None  # a folder of mesh files (.obj, .stl, .ply, ...) or one mesh file
    robot: Free = None  # the robot group as composed (configs/robot/), a name or a YAML path
    scale: float = setting(1.0, lo=0.0, lo_open=True, hi=MAX_SCALE)  # metres per mesh unit (0.001: millimetres)
    centre: list[float] | None = None  # where each object's bounding box is centred (world, m; None: OBJECT_CENTRE,
    # in front of a free hand; a hand on an arm needs it: where the arm reaches)
    fingers: list[str] | None = None  # the fingers that touch (None: the hand's opposing finger and its two nearest
    # neighbours, found from its kinematics: robot/opposition.py)
    grasps: int = setting(5, lo=1, hi=1000)  # the N best grasps kept per object
    candidates: int = setting(64, lo=1, hi=100_000)  # contact sets drawn per object
    trials: int = setting(8, lo=1, hi=10_000)  # learners per solved contact set (start=random, proposal)
    start: str = setting("sampled", choices=START)  # sampled: each set's solve from its sampled posture; random,
    # proposal: the search from random starts or the robot's learned posture proposals
    power: bool = True  # where the pads' grasps do not hold: power grasps too (the palm on the object, any link
    # touching)
    seed: int = setting(0, lo=0, hi=MAX_SEED)
    verify: str = setting("physics", choices=("none", "physics"))  # physics: each grasp in MuJoCo until a push
    # fails (gt.check_until_failure)
    out: str | None = None  # the results folder (None: <run dir>/results)
    threads: int = setting(1, lo=1, hi=1024)
    progress: bool = True
    pictures: bool = True  # <out>/<stem>.png: the object's best grasps side by side


def find_meshes(objects: str | None) -> list[Path]:
    """The mesh files of ``objects=`` (a folder: its files with a mesh suffix, sorted; or one
    file), refused in one line when there is none or two would write the same result file."""
    if not objects:
        raise ConfigError("objects= is required: a folder of mesh files (.obj, .stl, .ply) or one mesh file")
    path = Path(objects).expanduser()
    suffixes = tuple("." + f for f in MESH_FORMATS)
    if path.is_dir():
        meshes = sorted(p for p in path.iterdir() if p.suffix.lower() in suffixes and p.is_file())
        if not meshes:
            raise ConfigError(f"objects={clip(objects, 120)}: no mesh files in the folder (expected "
                              f"{', '.join(suffixes)})")
    elif path.is_file():
        if path.suffix.lower() not in suffixes:
            raise ConfigError(f"objects={clip(objects, 120)}: not a mesh file (expected {', '.join(suffixes)})")
        meshes = [path]
    else:
        raise ConfigError(f"objects={clip(objects, 120)}: no such folder or file")
    stems: dict[str, Path] = {}
    for p in meshes:
        if p.stem in stems:
            raise ConfigError(f"objects={clip(objects, 120)}: {clip(stems[p.stem].name, 60)} and {clip(p.name, 60)} "
                              f"would both write {clip(p.stem, 60)}.json; rename one")
        stems[p.stem] = p
    return meshes


def _check_fingers(robot: Robot, fingers: Sequence[str]) -> None:
    """The robot and ``fingers`` can have contacts chosen (the checks of
    :func:`~graspnet_torch.tasks.auto_contacts.contact_fingers` and
    :func:`~graspnet_torch.synthesis.candidates.check_pad_fingers`), as a setting: :class:`ConfigError`."""
    try:
        chosen = contact_fingers(robot.finger_names, list(fingers), robot.name, "fingers")
        check_pad_fingers(carried_hand(robot), chosen)
    except ProblemError as e:
        raise ConfigError(str(e)) from None


def prepare_synthesize(cfg: Mapping[str, Any] | SynthesizeGraspsJobCfg, run_dir: str | Path
                       ) -> tuple[SynthesizeGraspsJobCfg, RobotCfg, list[Path], Path]:
    """Every check of the job, before any work and without writing anything: the settings, the
    mesh files, the robot (loaded: cached for the job), its fingers and, where the sets are solved
    by the search (``start`` random or proposal), its FCNN checkpoint, the output folder.

    Returns:
        the settings, the robot's config, the mesh files and the results folder.
    """
    job = build(SynthesizeGraspsJobCfg, cfg)
    meshes = find_meshes(job.objects)
    robot_cfg = robot_cfg_from_setting(job.robot if job.robot is not None else "hand")
    robot = load_robot(robot_cfg)
    jaws = robot_kind(robot).schema.targets == "points"  # a gripper: its two marked points, no fingers
    if not jaws:
        if job.fingers is None:
            job = replace(job, fingers=list(default_fingers(carried_hand(robot))))
        _check_fingers(robot, job.fingers)
        if job.start != "sampled":  # the search: the robot's FCNN (refused if missing or corrupted)
            finger_ik_for(robot)
    elif job.verify == "physics":
        raise ConfigError(f"verify=physics: robot {robot.name}'s jaws do not move (fixed marked points): nothing to "
                          f"check in physics; verify=none")
    if job.centre is not None:
        number_list(job.centre, 3, "centre", ConfigError, -MAX_LENGTH_M, MAX_LENGTH_M, "number (m)")
    elif robot.has_body:
        raise ConfigError(f"centre=[x,y,z] is required for robot {robot.name} (a hand on an arm): where its objects "
                          f"lie in the world, within the arm's reach")
    out = Path(job.out).expanduser() if job.out else Path(run_dir) / "results"
    if out.exists() and not out.is_dir():
        raise ConfigError(f"out={clip(str(out), 120)}: exists and is not a folder")
    check_output_path(str(out / "summary.csv"), "out", ConfigError)  # the folder can be made and written in
    if job.verify == "physics":
        try:
            import mujoco  # noqa: F401  (only whether it imports)
        except ImportError:
            raise ConfigError("verify=physics needs MuJoCo: pip install mujoco (or verify=none)") from None
    return job, robot_cfg, meshes, out


def object_shape(path: Path, scale: float, centre: Sequence[float] | None = None) -> Shape:
    """The mesh as the problem's object, its bounding box centred at ``centre`` (None:
    :data:`OBJECT_CENTRE`; :func:`~graspnet_torch.tasks.objects.centred_mesh`); a file that is not a
    solid mesh trimesh reads: a :class:`ProblemError`."""
    check_mesh(path, "objects", scale)
    return centred_mesh(path, scale, OBJECT_CENTRE if centre is None else tuple(float(c) for c in centre))


def _row(name: str, grasps: list[dict], seconds: float, reason: str | None) -> dict:
    """The summary row of one object (``grasps``: its result file's, best first)."""
    holds = [g["holds"] for g in grasps if g.get("holds") is not None]
    full = [g["physics"]["of"] for g in grasps if g.get("physics")]
    checked = bool(holds) and len(holds) == len(grasps)
    pen = [g.get("penetration_mm") for g in grasps]
    pen = [p for p in pen if p is not None]
    return {"object": name, "grasps": len(grasps), "top1_type": grasps[0].get("type") if grasps else None,
            "best_holds": max(holds) if holds else None,
            "top1_holds_all": (grasps[0]["holds"] == full[0]) if checked else None,
            "top5_any_holds_all": any(h == n for h, n in zip(holds[:5], full[:5], strict=True)) if checked else None,
            "best_epsilon": max(g["quality"]["epsilon"] for g in grasps) if grasps else None,
            "deepest_penetration_mm": max(pen) if pen else None, "seconds": round(seconds, 2), "reason": reason}


def _synthesize_one(robot: Robot, path: Path, job: SynthesizeGraspsJobCfg, physics) -> tuple[dict, list]:
    """The result file's content for one object (a mesh that fails, or no grasp: with its reason)
    and its grasps."""
    t0 = time.perf_counter()
    stats: dict = {}
    data: dict = {"object": {"file": str(path.resolve()), "scale": job.scale, "pose": None}, "robot": robot.name,
                  "settings": {"fingers": list(job.fingers or ()), "grasps": job.grasps, "candidates": job.candidates,
                               "trials": job.trials, "start": job.start, "power": job.power, "seed": job.seed,
                               "verify": job.verify},
                  "stats": stats, "grasps": [], "reason": None}
    grasps: list[dict] = []
    found: list = []
    try:
        obj = object_shape(path, job.scale, job.centre)
        data["object"]["pose"] = obj.to_mapping()["pose"]  # m and degrees, as a problem file's
        found = synthesize_grasps(robot, obj, n_grasps=job.grasps, fingers=job.fingers,
                                  candidates=job.candidates, seed=job.seed, trials=job.trials, physics=physics,
                                  stats=stats, start=job.start, power=job.power)
        grasps = [g.to_dict() for g in found]
        if not grasps:
            data["reason"] = no_grasp_reason(stats)
    except GraspnetError as exc:
        data["reason"] = " ".join(str(exc).split())
    except Exception as exc:  # trimesh and the solver on an odd mesh: recorded, the other objects go on
        data["reason"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    if data["reason"]:
        data["reason"] = clip(data["reason"], 300)
    data["grasps"] = grasps
    data["seconds"] = round(time.perf_counter() - t0, 3)
    data["summary"] = _row(path.name, grasps, data["seconds"], data["reason"])
    return data, found


def _existing_row(path: Path, result: Path) -> dict:
    """The summary row of an object done before (its result file's), or one saying why not."""
    try:
        row = json.loads(result.read_text())["summary"]
        if isinstance(row, dict) and set(COLUMNS) <= set(row):
            return row
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return {**dict.fromkeys(COLUMNS), "object": path.name, "grasps": 0,
            "reason": f"{result.name} exists but is not this job's result: delete it to synthesize again"}


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: "" if row.get(k) is None else row[k] for k in COLUMNS})
    return buf.getvalue()


def _line(row: dict) -> str:
    if row["reason"]:
        return f"{row['object']}: {row['reason']}"
    held = "" if row["best_holds"] is None else f", best holds {row['best_holds']}"
    return f"{row['object']}: {row['grasps']} grasp(s){held}, {row['seconds']:.1f} s"


def synthesize_objects(job: SynthesizeGraspsJobCfg, robot_cfg: RobotCfg | str, meshes: Sequence[Path],
                       out: str | Path) -> list[dict]:
    """Grasps of each mesh (module docstring): ``<out>/<stem>.json`` per object (skipped when it
    exists), then ``<out>/summary.csv``; prints one line per object and the summary table.

    Returns:
        the summary rows, one per mesh, in order (:data:`COLUMNS`).
    """
    import torch

    from graspnet_torch.experiments.report import progress

    torch.set_num_threads(job.threads)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    robot = load_robot(robot_cfg)
    physics = check_until_failure if job.verify == "physics" else None
    rows = []
    items = progress(meshes, total=len(meshes), desc="objects", unit="object") if job.progress else iter(meshes)
    for path in items:
        stop_if_interrupted()  # a Ctrl-C that a library swallowed (trimesh's imports) stops before the next object
        result = out / f"{path.stem}.json"
        if result.exists():
            rows.append(_existing_row(path, result))
            print(f"{path.name}: skipped, {result} exists", flush=True)
            continue
        data, found = _synthesize_one(robot, path, job, physics)
        atomic_write_text(result, json.dumps(data, indent=1))
        if job.pictures and found:  # after the result: a failure is a warning
            warn_on_failure("picture", render_grasps, robot, found, out / f"{path.stem}.png", path.stem)
        rows.append(data["summary"])
        print(_line(data["summary"]), flush=True)
    atomic_write_text(out / "summary.csv", _csv(rows))
    table = [[r[k] if r[k] is not None else "-" for k in COLUMNS[:-1]] for r in rows]
    print(format_table(list(COLUMNS[:-1]), table, floatfmt=".3g"))
    print(f"{len(rows)} object(s), {sum(1 for r in rows if r['grasps'])} with grasps: {out / 'summary.csv'}")
    return rows


def prepare_auto(cfg: Mapping[str, Any], run_dir: str | Path) -> tuple[Any, GraspProblem, Robot, Path]:
    """Every check of a ``contacts: auto`` solve before any work and without writing anything: the
    settings, the problem, the output path, the robot and its fingers' pads. Returns the job's
    settings, the problem, the robot and the result path."""
    job, _, robot_setting = job_settings(cfg)
    problem = resolve_problem(job.problem, job.task, robot_setting, job.allow_outside_paths)
    if problem.auto is None:
        raise ConfigError(f"{problem.source}: not a contacts: auto problem")
    out = check_output_path(job.out or str(Path(run_dir) / "result.json"), "out", ConfigError)
    robot = load_robot(problem.robot_cfg)
    if problem.auto.fingers:  # a hand (a gripper's points: auto has none)
        try:
            check_pad_fingers(carried_hand(robot), problem.auto.fingers)  # names, count: checked as the file was read
        except ProblemError as e:
            raise ConfigError(str(e)) from None
    return job, problem, robot, out


def solve_auto_problem(cfg: Mapping[str, Any], run_dir: str | Path) -> dict:
    """``scripts/solve_grasp.py problem=P`` where P says ``contacts: auto``: the contacts chosen on
    its object (:func:`gt.synthesize_grasps`, its ``fingers`` and ``grasps``; ``seed``, ``trials``
    (at most 8) and ``threads`` from the command line), each grasp checked in MuJoCo where
    ``mujoco`` is installed (not a gripper's: its jaws do not move), and ``out`` (default
    ``<run dir>/result.json``) written atomically: the
    best grasp's fields at the top level (a result's, with its ``contacts``), the problem, ``auto``
    (the fingers and grasps asked for) and ``grasps``, best first (as in a ``synthesize_grasps.py``
    result); ``success``: a grasp found."""
    job, problem, robot, out = prepare_auto(cfg, run_dir)
    auto = problem.auto
    jaws = not auto.fingers  # a gripper: its jaws do not move, nothing to squeeze in physics
    physics = check_until_failure if importlib.util.find_spec("mujoco") is not None and not jaws else None
    torch.set_num_threads(job.threads)
    t0, stats = time.perf_counter(), {}
    found = synthesize_grasps(robot, problem.object, n_grasps=auto.grasps, fingers=auto.fingers,
                              candidates=max(CANDIDATES_PER_GRASP * auto.grasps, 64), seed=job.seed,
                              trials=min(job.trials, 8), physics=physics, stats=stats, obstacles=problem.obstacles)
    grasps = [g.to_dict() for g in found]
    best = dict(grasps[0]) if grasps else {"success": False, "reason": no_grasp_reason(stats)}
    data = {**best, "problem": problem.source, "robot": robot.name,
            "auto": {"fingers": list(auto.fingers), "grasps": auto.grasps}, "object": problem.object.to_mapping(),
            "physics_checked": physics is not None, "grasps": grasps, "stats": stats,
            "seconds": round(time.perf_counter() - t0, 3)}
    atomic_write_text(out, json.dumps(data, indent=1, allow_nan=False))
    if job.pictures and found:
        warn_on_failure("picture", render_grasps, robot, found, Path(run_dir) / "grasps.png", problem.name or "")
    held = sum(g["holds"] == g["physics"]["of"] for g in grasps if g.get("physics"))
    checked = f", {held} holding all 6 pushes in MuJoCo" if physics is not None else \
        " (a gripper whose jaws do not move: nothing to check in physics)" if jaws else \
        " (mujoco is not installed: not checked in physics)"
    print(f"{problem.name or problem.source}: {len(grasps)} grasp(s) on {'points' if jaws else 'contacts'} chosen on "
          f"the object{checked}; {data['seconds']:.1f} s")
    print(f"result: {out}")
    return data
