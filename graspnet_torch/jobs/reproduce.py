"""``scripts/reproduce.py``: the paper's experiments, one report.

Every experiment (:mod:`graspnet_torch.experiments`) runs in turn with its settings from
``configs/experiment/<name>.yaml`` (or only those given with ``+experiment=NAME``); their reports
become one ``REPRODUCTION.md`` (ours beside the paper's numbers, each figure beside its caption,
the machine and the seeds, and what does not match the paper) and ``reproduction.json`` (every
number, so that two runs can be compared: :func:`compare_numbers`). The report is then read back
and every table and figure the experiments promised is checked for: a missing one is an error
(exit 1), which is what CI's ``make reproduce-quick`` relies on.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from graspnet_torch.errors import ConfigError, InternalError
from graspnet_torch.experiments import EXPERIMENTS
from graspnet_torch.experiments.report import machine, progress, quick_settings
from graspnet_torch.io import atomic_write_text
from graspnet_torch.paths import configs_dir
from graspnet_torch.settings import Free, build, clip, setting
from graspnet_torch.table import markdown_table

__all__ = ["ReproduceJobCfg", "check_complete", "compare_numbers", "missed_targets", "prepare_reproduce", "reproduce",
           "shipped_experiments"]

REPORT = "REPRODUCTION.md"
NUMBERS = "reproduction.json"


@dataclass(frozen=True)
class ReproduceJobCfg:
    """``scripts/reproduce.py`` (configs/reproduce.yaml)."""

    experiments: Free = None  # {name: settings}; None: every shipped experiment
    quick: bool = False
    out: str | None = None  # None: the run folder
    threads: int = setting(1, lo=1, hi=1024)
    check: bool = False  # exit 1 when one of this project's targets is missed (the benchmarks' --check)


@dataclass(frozen=True)
class ReproducePlan:
    """What a reproduction will run: (name, settings) in order, where it writes, and how."""

    experiments: list[tuple[str, Any]]
    out: Path
    quick: bool
    threads: int
    check: bool = False


def shipped_experiments() -> dict[str, Any]:
    """Every experiment's settings as shipped (``configs/experiment/<name>.yaml``), in the
    order of :data:`~graspnet_torch.experiments.EXPERIMENTS`."""
    from omegaconf import OmegaConf

    out = {}
    for name in EXPERIMENTS:
        data = OmegaConf.to_container(OmegaConf.load(configs_dir() / "experiment" / f"{name}.yaml"), resolve=True)
        out[name] = data["experiments"][name]
    return out


def prepare_reproduce(cfg: Mapping[str, Any], run_dir: str) -> ReproducePlan:
    """The job's settings checked, every experiment's settings built (a mistake is a
    :class:`ConfigError` naming the key, before any work), and the output folder checked."""
    job = build(ReproduceJobCfg, cfg)
    chosen = job.experiments if job.experiments is not None else shipped_experiments()
    if not isinstance(chosen, Mapping) or not chosen:
        raise ConfigError("experiments: expected a mapping of experiment settings (or null: every experiment), "
                          f"got {clip(repr(chosen), 60)}")
    unknown = [name for name in chosen if name not in EXPERIMENTS]
    if unknown:
        raise ConfigError(f"unknown experiment '{clip(str(unknown[0]), 60)}': expected one of "
                          f"{', '.join(EXPERIMENTS)} (configs/experiment/)")
    plan = [(name, quick_settings(EXPERIMENTS[name].cfg, chosen[name], job.quick, f"experiments.{name}"))
            for name in EXPERIMENTS if name in chosen]
    out = Path(job.out) if job.out else Path(run_dir)
    for parent in (out, *out.parents):
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"out: {clip(str(parent), 200)} is a file, not a folder")
            break
    return ReproducePlan(plan, out, job.quick, job.threads, job.check)


def reproduce(plan: ReproducePlan, overrides: Sequence[str] = ()) -> Path:
    """Run every experiment of ``plan`` into ``plan.out``; write ``REPRODUCTION.md`` and
    ``reproduction.json`` (atomically, once all have run) and check them (:func:`check_complete`)."""
    import torch

    torch.set_num_threads(plan.threads)
    plan.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    reports = []
    names = [name for name, _ in plan.experiments]
    print(f"reproducing {', '.join(names)}{' (quick: the reduced protocol)' if plan.quick else ''} into {plan.out} "
          f"({torch.get_num_threads()} torch thread)", flush=True)
    for k, (name, cfg) in enumerate(progress(plan.experiments, desc="reproduce", unit="experiment")):
        t0 = time.perf_counter()
        report = EXPERIMENTS[name].run(cfg, plan.out)
        report.seconds = time.perf_counter() - t0
        report.settings = _plain(dataclasses.asdict(cfg))
        reports.append(report)
        print(f"[{k + 1}/{len(names)}] {name}: {report.seconds:.0f} s, {len(report.mismatches)} mismatch(es) with the "
              f"paper", flush=True)
    total = time.perf_counter() - started
    info = machine()
    text = render(reports, info, total, plan.quick, overrides)
    atomic_write_text(plan.out / NUMBERS, json.dumps(
        {"machine": info, "quick": plan.quick, "seconds": total, "overrides": list(overrides),
         "experiments": {r.name: {"settings": r.settings, "numbers": r.numbers, "timings": r.timings,
                                  "seconds": r.seconds, "mismatches": r.mismatches,
                                  "checks": [[what, ok] for what, ok in r.checks]} for r in reports}},
        indent=1, default=float) + "\n")
    path = atomic_write_text(plan.out / REPORT, text)
    check_complete(plan.out, reports)
    print(f"wrote {path} and {plan.out / NUMBERS} ({total / 60:.1f} min)")
    return path


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    keep = "".join(c for c in title.lower() if c.isalnum() or c in " -_")
    return keep.replace(" ", "-")


def render(reports: list, info: Mapping[str, str], seconds: float, quick: bool, overrides: Sequence[str] = ()) -> str:
    """``REPRODUCTION.md``: the machine and seeds, what does not match, then one section per experiment."""
    command = "make reproduce-quick" if quick else "make reproduce"
    lines = ["# Reproducing Rezzoug & Gorce, \"Robotic Grasping: A Generic Neural Network Architecture\"", "",
             f"Written by `{command}` (`python scripts/reproduce.py{' ' + ' '.join(overrides) if overrides else ''}`) "
             f"on {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC in {seconds / 60:.1f} min. Each experiment is a "
             "Hydra experiment config (`configs/experiment/`): `python scripts/reproduce.py +experiment=NAME` runs "
             "it alone, and its settings can be overridden and swept (`experiments.NAME.KEY=...`). The same seeds "
             "give the same numbers (`reproduction.json`), except the wall-clock ones, listed last.", ""]
    if quick:
        lines += ["**Reduced protocol** (`quick=true`): fewer runs and shorter budgets, the same code path. These "
                  "numbers check that every experiment runs; they are not the paper's protocol.", ""]
    lines += ["## Contents", ""]
    lines += [f"- [{r.title}](#{_anchor(r.title)})" for r in reports]
    lines += ["- [What does not match the paper](#what-does-not-match-the-paper)",
              "- [Machine, settings and seeds](#machine-settings-and-seeds)",
              "- [Numbers that vary from run to run](#numbers-that-vary-from-run-to-run)", ""]
    for r in reports:
        lines.append(r.markdown(f"python scripts/reproduce.py +experiment={r.name}", "##", quick, mismatches=False))
    lines += ["## What does not match the paper", ""]
    mismatches = [(r.title, m) for r in reports for m in r.mismatches]
    lines += [f"- {m}" for _, m in mismatches] or ["- Nothing measured here differs from the paper."]
    lines += ["", "## Machine, settings and seeds", "",
              markdown_table(["machine", ""], [[k, v] for k, v in info.items()]), "",
              markdown_table(["experiment", "settings (seeds included)", "time (s)"],
                           [[r.name, "`" + json.dumps(r.settings, separators=(", ", ": ")) + "`", f"{r.seconds:.0f}"]
                            for r in reports]), "",
              "## Numbers that vary from run to run", "",
              "Wall times, rates, and the errors reached within a wall-time budget (Table 2's time columns) depend on "
              "the machine and its load: the machine table's `sum(range(10**6)) ms` (one core's speed, measured as the "
              "report is written) compares two machines.", ""]
    rows = [[r.name, key, "never" if value is None else f"{value:.4g}"] for r in reports
            for key, value in r.timings.items()]
    lines += [markdown_table(["experiment", "what", "value"], rows) if rows else "(none)", ""]
    return "\n".join(lines)


def check_complete(out: Path, reports: list) -> None:
    """Read ``REPRODUCTION.md`` back: every experiment's section, every table it promised (a
    markdown table under its heading) and every figure (a non-empty PNG, linked); raise
    :class:`InternalError` naming the first one missing."""
    text = (out / REPORT).read_text(encoding="utf-8")
    sections = text.split("\n## ")
    for r in reports:
        section = next((s for s in sections if s.startswith(r.title)), None)
        if section is None:
            raise InternalError(f"{out / REPORT}: the section of {r.name} ({r.title}) is missing")
        for table in r.tables:
            if table not in section or "|---" not in section:
                raise InternalError(f"{out / REPORT}: {table} is missing from the section of {r.name}")
        for fig in r.figures:
            png = out / fig.file
            if not png.is_file() or png.stat().st_size == 0 or f"]({fig.file})" not in section:
                raise InternalError(f"{out / REPORT}: figure {fig.file} of {r.name} is missing or empty")


def compare_numbers(a: str | Path, b: str | Path) -> list[str]:
    """The numbers of two ``reproduction.json`` files that differ (timings are not compared):
    one line each; empty when the runs agree exactly."""
    first, second = (json.loads(Path(p).read_text(encoding="utf-8"))["experiments"] for p in (a, b))
    out = []
    for name in sorted(set(first) | set(second)):
        x, y = first.get(name, {}).get("numbers", {}), second.get(name, {}).get("numbers", {})
        for key in sorted(set(x) | set(y)):
            u, v = x.get(key), y.get(key)
            same = u == v or (isinstance(u, float) and isinstance(v, float) and math.isnan(u) and math.isnan(v))
            if not same:
                out.append(f"{name}: {key}: {u} vs {v}")
    return out


def missed_targets(numbers: str | Path) -> list[str]:
    """This project's targets that a ``reproduction.json`` records as missed, one line each
    (``experiment: what``); empty when every one was met."""
    data = json.loads(Path(numbers).read_text(encoding="utf-8"))["experiments"]
    return [f"{name}: {what}" for name, r in data.items() for what, ok in r.get("checks", []) if not ok]
