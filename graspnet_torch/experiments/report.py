"""What every experiment of the paper returns, and the helpers they share.

An experiment (:mod:`graspnet_torch.experiments`) runs one part of the paper's evaluation and
returns an :class:`ExperimentReport`: a markdown body (ours beside the paper's numbers), its
figures (PNG files beside their captions), the numbers that the same seeds must reproduce exactly,
the wall-clock figures that differ from run to run, and what does not match the paper, said plainly.
:func:`graspnet_torch.jobs.reproduce.reproduce` puts the reports together in ``REPRODUCTION.md``.
"""

from __future__ import annotations

import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.settings import build, short
from graspnet_torch.solver.api import solve, solve_many
from graspnet_torch.solver.config import SolverCfg

__all__ = ["ExperimentReport", "Figure", "machine", "mean_std", "progress", "quick_settings", "require"]

T = TypeVar("T")


@dataclass(frozen=True)
class Figure:
    """A PNG written by an experiment (``file``: its name in the output folder) and its caption."""

    file: str
    caption: str


@dataclass
class ExperimentReport:
    """One experiment's results.

    Attributes:
        name: the experiment (``table2``: ``+experiment=table2``).
        title: the section heading (``Table 2: ...``).
        body: markdown: how it was run, then ours beside the paper's numbers.
        figures: the PNGs it wrote, in order, with their captions.
        tables: the paper's tables this body holds (``Table 2``), checked for by ``reproduce``.
        numbers: every result that the same seeds reproduce exactly (errors, counts, statistics).
        timings: wall-clock results (seconds, rates, and what a time budget bought): they vary;
            None: never reached (a time to something that did not happen).
        mismatches: what does not match the paper, one sentence each.
        checks: this project's own targets (the issues'): (what, met).
        settings: the experiment's settings as run.
        seconds: its wall time.
        results: the raw results, for a caller that goes on with them (not written anywhere).
    """

    name: str
    title: str
    body: str
    figures: list[Figure] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    numbers: dict[str, float] = field(default_factory=dict)
    timings: dict[str, float | None] = field(default_factory=dict)
    mismatches: list[str] = field(default_factory=list)
    checks: list[tuple[str, bool]] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    results: Any = field(default=None, repr=False)

    def markdown(self, command: str, heading: str = "#", quick: bool = False, mismatches: bool = True) -> str:
        """The report as markdown: its title under ``heading``, the command that made it, the body,
        each figure beside its caption, this project's targets, and (``mismatches``) what does not
        match the paper."""
        lines = [f"{heading} {self.title}", "", f"_`{command}` ({self.seconds:.0f} s here)_", "", self.body.rstrip(),
                 ""]
        for fig in self.figures:
            lines += [f"![{fig.caption}]({fig.file})", "", f"*{fig.caption}*", ""]
        if self.checks:
            scope = " (they apply to the full protocol, not to this reduced one)" if quick else ""
            lines += [f"This project's targets{scope}:", ""]
            lines += [f"- {'met' if ok else 'MISSED'}: {what}" for what, ok in self.checks]
            lines.append("")
        if mismatches:
            lines += [f"{heading}# What does not match the paper", ""]
            lines += [f"- {m}" for m in self.mismatches] or ["- Nothing measured here differs from the paper."]
            lines.append("")
        return "\n".join(lines)


def mean_std(values: Iterable[float], digits: int = 2) -> str:
    """``"m +- s"`` (sample standard deviation; 0 for one value)."""
    v = np.asarray(list(values), dtype=float)
    s = v.std(ddof=1) if v.size > 1 else 0.0
    return f"{v.mean():.{digits}f} +- {s:.{digits}f}"


def progress(iterable: Iterable[T], total: int | None = None, desc: str = "", unit: str = "it") -> Iterator[T]:
    """``iterable`` with a progress bar and an estimate of the time left on stderr; quiet when
    stderr is not a terminal (a log, CI)."""
    from tqdm.auto import tqdm

    return iter(tqdm(iterable, total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True))


@dataclass(frozen=True)
class ArmCell:
    """One solver on one arm environment over seeds (:func:`arm_cell`): successes (the best trial
    collision-free with total error < 1 mm), and per seed its mean iterations per trial, best
    error (mm) and wall time (s)."""

    ok: int
    iterations: list[float]
    error_mm: list[float]
    wall_s: list[float]


def arm_cell(env: str, seeds: int, solver: SolverCfg | dict, trials: int = 16, first: int = 1000) -> ArmCell:
    """``gt.solve(env, trials=trials, seed=s, solver=solver)`` for the seeds ``first`` .. ``first + seeds - 1``."""
    ok, its, err, wall = 0, [], [], []
    for s in range(seeds):
        t0 = time.perf_counter()
        r = solve(env, trials=trials, seed=first + s, solver=solver)
        wall.append(time.perf_counter() - t0)
        ok += r.best.collisions == 0 and r.best.total_error_mm < 1.0
        its.append(float(np.mean([t.iterations for t in r.trials])))
        err.append(r.best.total_error_mm)
    return ArmCell(ok, its, err, wall)


@dataclass(frozen=True)
class BatchCell:
    """One solver on a batch of gripper problems (:func:`batch_cell`): the results, the call's
    wall time (s), and every learner's d (mm), collision count and iterations."""

    results: list
    wall_s: float
    distance_mm: np.ndarray
    collisions: np.ndarray
    iterations: np.ndarray


def batch_cell(problems: list, runs: int, solver: SolverCfg | dict) -> BatchCell:
    """``gt.solve_many(problems, trials=runs, seed=0, solver=solver)``, timed, its learners' figures."""
    t0 = time.perf_counter()
    results = solve_many(problems, trials=runs, seed=0, solver=solver)
    wall = time.perf_counter() - t0
    trials = [t for r in results for t in r.trials]
    return BatchCell(results, wall, np.array([t.distance_mm for t in trials]), np.array([t.collisions for t in trials]),
                     np.array([t.iterations for t in trials]))


def require(ok: bool, message: str) -> None:
    """A settings check beyond a field's type and range: :class:`ConfigError` with ``message``."""
    if not ok:
        raise ConfigError(message)


def quick_settings(cls: type[T], data: Mapping[str, Any] | None, quick: bool, where: str = "") -> T:
    """``cls`` from an experiment's config: its settings, and with ``quick`` its ``quick`` block of
    overrides on top (the reduced protocol: fewer runs, the same code path); ``where`` names the
    settings in messages (``experiments.table2``)."""
    if data is not None and not isinstance(data, Mapping):
        raise ConfigError(f"{where or cls.__name__}: expected a mapping of settings, got {short(data)}")
    data = dict(data or {})
    overrides = data.pop("quick", None) or {}
    if not isinstance(overrides, Mapping):
        raise ConfigError(f"{where}.quick: expected a mapping of settings, got {short(overrides)}")
    build(cls, overrides, f"{where}.quick" if where else "quick")  # its keys and values are checked even when not used
    return build(cls, {**data, **(dict(overrides) if quick else {})}, where)


def _cpuinfo(key: str) -> str | None:
    """The first value of ``key`` in /proc/cpuinfo (None: none, or no such file)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith(key):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def _cpu_name() -> str:
    return _cpuinfo("model name") or platform.processor() or platform.machine()


def _git_commit(root: Path) -> str:
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             timeout=5, check=False)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    commit = out.stdout.strip() or "unknown"
    return commit + (" (with uncommitted changes)" if dirty.stdout.strip() else "")


PACKAGES = ("numpy", "mujoco", "trimesh", "python-fcl", "coacd")  # the versions a reproduction names


def _cpu_mhz() -> str:
    mhz = _cpuinfo("cpu MHz")
    try:
        return f"{float(mhz):.0f}" if mhz else "unknown"
    except ValueError:
        return "unknown"


def python_speed_ms() -> float:
    """A machine's single-thread speed, to compare wall-clock figures across machines: the best of
    5 runs of ``sum(range(10**6))`` in ms (a 3 GHz x86 core: about 10-15 ms)."""
    best = math.inf
    for _ in range(5):
        t0 = time.perf_counter()
        sum(range(10**6))
        best = min(best, time.perf_counter() - t0)
    return best * 1000


def _versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    def one(name: str) -> str:
        try:
            return f"{name} {version(name)}"
        except PackageNotFoundError:
            return f"{name} -"

    return ", ".join(one(n) for n in PACKAGES)


def machine() -> dict[str, str]:
    """The machine a reproduction ran on: CPU (its clock, MHz), cores, its single-thread speed
    (:func:`python_speed_ms`), Python, torch and its threads, the other packages whose versions move
    figures (``PACKAGES``), the commit."""
    import torch

    return {"cpu": _cpu_name(), "cpu MHz": _cpu_mhz(), "cores": str(os.cpu_count()),
            "sum(range(10**6)) ms": f"{python_speed_ms():.1f}",
            "os": f"{platform.system()} {platform.release()}", "python": sys.version.split()[0],
            "torch": torch.__version__, "torch threads": str(torch.get_num_threads()), "packages": _versions(),
            "commit": _git_commit(repo_root())}
