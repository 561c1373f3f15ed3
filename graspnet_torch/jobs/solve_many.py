"""``solve_grasp.py problem=DIR`` or ``problem=FILE.jsonl``: many problems, one result each.

The grasp-dataset use case. Every problem file of a folder (``*.yaml``, ``*.yml``, ``*.json``,
sorted by name), or every line of a JSON-lines file (one problem mapping per line; blank lines
skipped), is read and checked before any work; then :func:`graspnet_torch.solve_many` solves them
``batch`` problems at a time (P x T trials as one vectorised search), with a progress bar, and
writes one result JSON per problem into the folder ``out`` (default ``<run dir>/results``):
``<file stem>.json`` for a folder, ``<name>.json`` (the problem's ``name``, else ``line<k>``)
for a JSON-lines file (characters other than letters, digits, ``.``, ``_`` and ``-`` become
``_``), each written atomically, plus ``summary.csv`` (one row per problem: its
success, error, collisions, iterations, trials reported and wall time). Every problem gets its
own file: a name already taken (ignoring case) gets ``-2``, ``-3``, ... (the first not taken).
Every problem (its file, or its line, strictly UTF-8) and every result path is checked before
any work: a result path that exists as anything but a regular file is refused.
No pictures or TensorBoard curves: those are for one problem.

With ``sequence=true`` the problems are the frames of a sequence (a hand following moving
contacts): solved in order by :meth:`graspnet_torch.Solver.iter_track`, each frame warm-started
from the previous frame's result and searched in full only where that does not land.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.files import read_document
from graspnet_torch.io import atomic_write_text
from graspnet_torch.jobs.configs import SolveGraspJobCfg, check_device, check_solve_memory
from graspnet_torch.jobs.interrupt import stop_if_interrupted
from graspnet_torch.jobs.solve_grasp import check_problem, job_settings, prepare_solve, solve_grasp, with_robot_defaults
from graspnet_torch.jobs.synthesize import prepare_auto, solve_auto_problem
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.settings import clip
from graspnet_torch.solver.api import solve_many
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.solver.session import Solver
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["is_many", "load_problems", "prepare_job", "prepare_many", "run_job", "solve_grasps"]

SUFFIXES = (".yaml", ".yml", ".json")
MAX_LINE_BYTES = 1 << 20


def is_many(problem: str | None) -> bool:
    """Whether ``problem=`` names many problems: a folder or a ``.jsonl`` file."""
    if not problem:
        return False
    p = Path(str(problem)).expanduser()
    return p.is_dir() or p.suffix.lower() == ".jsonl"


def load_problems(path: str | Path, robot: RobotCfg | str | None = None, allow_outside_paths: bool = False
                  ) -> list[tuple[str, GraspProblem]]:
    """(name, problem) of every problem of a folder or a JSON-lines file, validated, in order;
    one robot for all (``robot``: a config that replaces the shipped one of its name, or a name
    the problems must use). Names are unique file names (``-2``, ``-3``, ... where they repeat)."""
    p = Path(str(path)).expanduser()
    robot_cfg = robot if isinstance(robot, RobotCfg) else None
    named: list[tuple[str, GraspProblem]] = []
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in SUFFIXES and f.is_file())
        if not files:
            raise ProblemError(f"{clip(str(p), 200)}: no problem files ({', '.join('*' + s for s in SUFFIXES)}) in "
                               f"this folder")
        for f in files:
            try:
                f.name.encode("utf-8")
            except UnicodeEncodeError:  # undecodable bytes, kept by the file system as surrogates
                raise ProblemError(f"{clip(str(p), 200)}: the file name {ascii(os.fsencode(f.name))[2:-1]} is not "
                                   f"UTF-8 (problem files and their names are UTF-8); rename it") from None
            named.append((f.stem, GraspProblem.from_file(f, robot_cfg=robot_cfg,
                                                         allow_outside_paths=allow_outside_paths)))
    else:
        if not p.is_file():
            raise ProblemError(f"problem={clip(str(path), 200)}: no such file or folder")
        with p.open("rb") as fh:
            for k, raw in enumerate(iter(lambda: fh.readline(MAX_LINE_BYTES + 1), b""), 1):
                where = f"{clip(str(p), 200)}:{k}"
                if len(raw) > MAX_LINE_BYTES:  # read no further than the limit
                    raise ProblemError(f"{where}: a line over 1 MiB")
                if not raw.strip():
                    continue
                problem = GraspProblem.from_mapping(_json_line(raw, where), source=where, robot_cfg=robot_cfg,
                                                    folder=p.resolve().parent,
                                                    allow_outside_paths=allow_outside_paths)
                named.append((problem.name or f"line{k}", problem))
        if not named:
            raise ProblemError(f"{clip(str(p), 200)}: no problems (every line is blank)")
    name = robot_cfg.name if robot_cfg is not None else robot
    first = named[0][1]
    for _, problem in named:
        if name and problem.robot != name:
            raise ProblemError(f"{problem.source}: the problem is for robot '{problem.robot}', but robot="
                               f"{clip(str(name), 80)} was given")
        if problem.robot != first.robot:
            raise ProblemError(f"{problem.source}: robot '{problem.robot}' differs from the first problem's "
                               f"'{first.robot}' (one run, one robot)")
    return _unique([(_file_name(n), pr) for n, pr in named])


def _json_line(raw: bytes, where: str) -> Any:
    """One line of a JSON-lines file, parsed; refused in one line naming ``where`` (file:line)
    when it is not UTF-8, not JSON, nested too deeply or holds an integer of thousands of digits."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProblemError(f"{where}: not UTF-8 text (invalid byte at offset {exc.start})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{where}: not valid JSON ({exc.msg}, column {exc.colno})") from None
    except RecursionError:
        raise ProblemError(f"{where}: nested too deeply") from None
    except ValueError as exc:  # an integer literal with thousands of digits
        raise ProblemError(f"{where}: unreadable value ({clip(str(exc), 80)})") from None


def _file_name(name: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "problem"
    return safe[:100]


def _unique(named: list[tuple[str, GraspProblem]]) -> list[tuple[str, GraspProblem]]:
    """Result names that never collide, even on a file system that ignores case: each first use
    of a name keeps it; a repeat gets ``-2``, ``-3``, ... (the first not already taken)."""
    taken = {name.casefold() for name, _ in named}
    first: set[str] = set()
    out = []
    for name, problem in named:
        key = name.casefold()
        if key not in first:
            first.add(key)
            out.append((name, problem))
            continue
        k = 2
        while f"{name}-{k}".casefold() in taken:
            k += 1
        taken.add(f"{name}-{k}".casefold())
        out.append((f"{name}-{k}", problem))
    return out


def prepare_many(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path
                 ) -> tuple[SolveGraspJobCfg, list[tuple[str, GraspProblem]], torch.device, Path, SolverCfg]:
    """Every check before any work, without writing anything: the settings, the device, every
    problem (as :func:`~graspnet_torch.jobs.solve_grasp.prepare_solve` checks one), the output
    folder (a folder or nothing yet, writable) and the memory of one batch."""
    job, groups, robot = job_settings(cfg)
    if job.reach.enabled:
        raise ConfigError("reach=true plans the motion of one problem: give problem=FILE (a folder or .jsonl "
                          "of problems: plan each result's motion with gt.plan_reach)")
    if job.verify != "none":
        raise ConfigError(f"verify={job.verify} checks the result of one problem: give problem=FILE (a folder or "
                          f".jsonl of problems: check each result with gt.simulate_grasp)")
    device = check_device(job.device)
    named = load_problems(job.problem, robot, job.allow_outside_paths)
    problems = [p for _, p in named]
    job, solver = with_robot_defaults(job, groups, problems[0].robot_cfg)
    out = Path(job.out or Path(run_dir) / "results").expanduser()
    _check_out_folder(out, [f"{name}.json" for name, _ in named] + ["summary.csv"])
    per_batch = min(job.batch, len(problems))
    check_solve_memory(job.trials * per_batch, solver.max_iterations, max(len(p.contacts) for p in problems),
                       solver.history, 4 if solver.dtype == "float32" else 8, device, job.srv.hidden)
    for p in problems:
        check_problem(p, solver)
    return job, named, device, out, solver


def problems_robot(named: Sequence[tuple[str, GraspProblem]]) -> RobotCfg | str:
    """The robot of a list of problems: the first's config (a robot by path), else its name."""
    first = named[0][1]
    return first.robot_cfg or first.robot


def _check_out_folder(out: Path, files: Sequence[str]) -> None:
    """The output folder: a folder or nothing yet, writable; each of ``files`` in it a regular
    file or nothing yet (a folder, a device or a broken link of a result's name is never replaced)."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"out={clip(str(out), 120)}: exists and is not a folder (many problems write one result "
                          f"each into a folder)")
    if out.is_dir():
        for name in files:
            target = out / name
            if os.path.lexists(target) and not target.is_file():
                what = "a folder" if target.is_dir() else "not a regular file"
                raise ConfigError(f"out={clip(str(out), 120)}: {clip(name, 110)} in it is {what}, where a result "
                                  f"goes; it is never replaced (move it, or give another out=)")
    probe = out
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ConfigError(f"out={clip(str(out), 120)}: {clip(str(probe), 120)} is not a folder")
    import tempfile

    try:
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=".probe-")
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise ConfigError(f"out={clip(str(out), 120)}: cannot write in {clip(str(probe), 120)} "
                          f"({exc.strerror})") from None


def solve_grasps(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path) -> list[GraspResult]:
    """The job behind ``solve_grasp.py problem=DIR`` (or a ``.jsonl`` file): every problem
    checked first (a refusal writes nothing), then solved ``batch`` at a time; one result JSON per
    problem and ``summary.csv`` in the output folder. Returns the results in order."""
    from tqdm.auto import tqdm

    job, named, device, out, solver = prepare_many(cfg, run_dir)
    torch.set_num_threads(job.threads)
    out.mkdir(parents=True, exist_ok=True)
    results: list[GraspResult] = []
    t0 = time.perf_counter()
    with tqdm(total=len(named), unit="frame" if job.sequence else "problem", desc="solving", disable=None) as bar:
        if job.sequence:  # frames in order, each from the last
            tracker = Solver(problems_robot(named), trials=job.trials, seed=job.seed, solver=solver, srv=job.srv,
                             reward=job.reward, noise=job.noise, device=device)
            for (name, _), result in zip(named, tracker.iter_track(p for _, p in named), strict=True):
                result.save(out / f"{name}.json")
                results.append(result)
                bar.update(1)
                stop_if_interrupted()  # a Ctrl-C that a library swallowed stops before the next frame
        for start in range(0, len(named) if not job.sequence else 0, job.batch):
            stop_if_interrupted()  # ... and before the next batch
            chunk = named[start:start + job.batch]
            batch = solve_many([p for _, p in chunk], trials=job.trials, seed=job.seed + start, solver=solver,
                               srv=job.srv, reward=job.reward, noise=job.noise, device=device)
            for (name, _), result in zip(chunk, batch, strict=True):
                result.save(out / f"{name}.json")
            results.extend(batch)
            bar.update(len(chunk))
    wall = time.perf_counter() - t0
    rows = ["name,problem,success,error_mm,collisions,iterations,trials,wall_time_s,failure"]
    rows += [f"{name},{_csv(r.problem)},{int(r.success)},{r.best.error_mm:.6g},{r.best.collisions},{r.best.iterations},"
             f"{len(r.trials)},{r.best.wall_time_s:.6g},{_csv(r.failure)}" for (name, _), r in zip(named, results,
                                                                                                  strict=True)]
    atomic_write_text(out / "summary.csv", "\n".join(rows) + "\n")
    errors = np.array([r.best.error_mm for r in results])
    solved = sum(r.success for r in results)
    how = (f"frames in order, {sum(len(r.trials) == 1 for r in results)} landed warm" if job.sequence else
           f"{job.trials} trials each, batches of {min(job.batch, len(results))}")
    print(f"{len(results)} problems (solver={solver.method}, {how}): {solved} succeeded "
          f"(within {solver.tolerance_mm:g} mm, collision-free); best error < 1 mm: {int((errors < 1).sum())}; "
          f"median {np.median(errors):.3g} mm; {wall:.1f} s ({len(results) / wall:.1f} problems/s)")
    print(f"results: {out}/ (one JSON per problem, summary.csv)")
    return results


def _csv(text: str | None) -> str:
    text = str(text or "")
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if any(c in text for c in ',"\n') else text


def _problem_setting(cfg: Mapping[str, Any] | SolveGraspJobCfg) -> str | None:
    value = cfg.get("problem") if isinstance(cfg, Mapping) else cfg.problem
    return value if isinstance(value, str) else None


def prepare_job(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path) -> None:
    """The checks of ``solve_grasp.py`` before any work: many problems or one."""
    if is_many(_problem_setting(cfg)):
        prepare_many(cfg, run_dir)
    elif _auto(cfg):
        prepare_auto(cfg, run_dir)
    else:
        prepare_solve(cfg, run_dir)


def run_job(cfg: Mapping[str, Any] | SolveGraspJobCfg, run_dir: str | Path, overrides: Sequence[str] = ()) -> None:
    """``solve_grasp.py``: many problems (a folder, a ``.jsonl`` file) or one (``overrides``: the
    job's command line, its TensorBoard hparams)."""
    if is_many(_problem_setting(cfg)):
        solve_grasps(cfg, run_dir)
    elif _auto(cfg):  # contacts: auto: chosen on the object (jobs/synthesize.py)
        solve_auto_problem(cfg, run_dir)
    else:
        solve_grasp(cfg, run_dir, overrides)


def _auto(cfg: Mapping[str, Any] | SolveGraspJobCfg) -> bool:
    """Whether the job's one problem file says ``contacts: auto`` (a gripper's: ``points: auto``; its
    refusals come later, from the job)."""
    path = _problem_setting(cfg)
    if not path:
        return False
    try:
        data = read_document(path, "problem file", ProblemError)
        return "auto" in (data.get("contacts"), data.get("points"))
    except (ProblemError, AttributeError):
        return False
