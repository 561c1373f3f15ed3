"""``scripts/summarize_sweep.py <sweep dir>``: a Hydra sweep of ``solve_grasp.py`` as a table and a plot.

Every job folder of the sweep (any launcher: basic, joblib, submitit) holds its ``result.json``
and ``.hydra/overrides.yaml``. The settings that differ between jobs are the swept parameters;
the summary has one row per job (the swept settings, success, best error, iterations, wall
time, collisions), one row per combination of the swept settings other than ``seed``
(aggregated over seeds: jobs, success rate, median and worst error, median wall time), and a
plot of the median error and the success rate against the first swept parameter, one line per
value of the second. Written as ``summary.csv`` (per job), ``summary.md`` (both tables) and
``summary.png`` into the sweep folder (or ``out``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from graspnet_torch.errors import ConfigError, say
from graspnet_torch.io import atomic_write_text
from graspnet_torch.settings import clip
from graspnet_torch.solver.environments import ENVIRONMENTS
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.table import markdown_table
from graspnet_torch.viz.plots import _plt
from graspnet_torch.viz.robot import save_figure

"""The result JSON keys of the ranked error, one per kind of environment."""

__all__ = ["collect_sweep", "summarize_sweep"]

METRICS = ("success", "error_mm", "iterations", "wall_time_s", "collisions")


def _value(text: str) -> float | int | str:
    try:
        return float(text) if any(c in text for c in ".eE") else int(text)
    except ValueError:
        return text


def collect_sweep(sweep: str | Path) -> tuple[list[str], list[dict]]:
    """(swept parameter names, one row per finished job: its folder, settings and metrics)."""
    root = Path(sweep).expanduser()
    if not root.is_dir():
        raise ConfigError(f"{clip(str(root), 200)}: not a folder (give the sweep folder of a -m run)")
    rows = []
    for result_path in sorted(root.rglob("result.json"), key=lambda p: (len(p.parts), str(p))):
        job = result_path.parent
        overrides = job / ".hydra" / "overrides.yaml"
        items = yaml.safe_load(overrides.read_text()) if overrides.is_file() else []
        settings = {}
        for item in items or []:
            key, sep, value = str(item).partition("=")
            if sep and not key.startswith(("hydra", "~")):
                settings[key.lstrip("+")] = _value(value)
        error_keys = tuple(dict.fromkeys(env.error_key for env in ENVIRONMENTS.values()))  # every kind's
        try:
            best = GraspResult.from_dict(json.loads(result_path.read_text()), error_keys=error_keys).best
        except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError):
            best = None
        if best is None or not isinstance(best.error_mm, int | float):
            raise ConfigError(f"{clip(str(result_path), 200)}: not a grasp result (no {' or '.join(error_keys)})")
        rows.append({"job": str(job.relative_to(root)), "settings": settings,
                     "success": bool(best.success), "error_mm": float(best.error_mm),
                     "iterations": int(best.iterations), "wall_time_s": float(best.wall_time_s),
                     "collisions": int(best.collisions)})
    if not rows:
        raise ConfigError(f"{clip(str(root), 200)}: no job results (result.json) below this folder")
    keys = sorted({k for r in rows for k in r["settings"]})
    swept = [k for k in keys if len({repr(r["settings"].get(k)) for r in rows}) > 1]
    return swept, rows


def _order(values: Sequence) -> list:
    numeric = all(isinstance(v, int | float) for v in values)
    return sorted(set(values), key=(lambda v: v) if numeric else str)


def summarize_sweep(sweep: str | Path, out: str | Path | None = None) -> dict[str, Path]:
    """Write ``summary.csv``, ``summary.md`` and ``summary.png`` of a sweep; returns their paths.
    A failure to draw the plot is a warning (the tables are written first)."""
    swept, rows = collect_sweep(sweep)
    folder = Path(out).expanduser() if out is not None else Path(sweep).expanduser()
    folder.mkdir(parents=True, exist_ok=True)
    header = ["job", *swept, *METRICS]
    per_job = [[r["job"], *(r["settings"].get(k, "") for k in swept), *(r[m] for m in METRICS)] for r in rows]
    csv = "\n".join(",".join(_csv(v) for v in row) for row in [header, *per_job]) + "\n"
    paths = {"csv": atomic_write_text(folder / "summary.csv", csv)}
    groups = [k for k in swept if k != "seed"]
    combos: dict[tuple, list[dict]] = {}
    for r in rows:
        combos.setdefault(tuple(r["settings"].get(k) for k in groups), []).append(r)
    agg = []
    for combo in sorted(combos, key=lambda c: [str(x) for x in c]):
        rs = combos[combo]
        e = np.array([r["error_mm"] for r in rs])
        agg.append([*combo, len(rs), f"{np.mean([r['success'] for r in rs]) * 100:.0f}", f"{np.median(e):.3g}",
                    f"{e.max():.3g}", f"{np.median([r['wall_time_s'] for r in rs]):.3g}"])
    md = (f"# Sweep {clip(str(sweep), 200)}\n\n{len(rows)} jobs; swept: {', '.join(swept) or 'nothing'}.\n\n"
          "## Per setting (over seeds)\n\n"
          + markdown_table([*groups, "jobs", "success %", "median error mm", "worst mm", "median wall s"], agg)
          + "\n\n## Per job\n\n" + markdown_table(header, per_job, floatfmt=".4g") + "\n")
    paths["md"] = atomic_write_text(folder / "summary.md", md)
    try:
        paths["png"] = _plot(rows, groups, folder / "summary.png", str(sweep))
    except Exception as exc:  # the tables are written; a plot failure only warns

        say(f"warning: summary.png not written: {type(exc).__name__}: {clip(str(exc), 200)}")
    return paths


def _plot(rows: list[dict], groups: list[str], path: Path, title: str) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), dpi=110)
    x_key = groups[0] if groups else None
    line_key = groups[1] if len(groups) > 1 else None
    xs = _order([r["settings"].get(x_key) for r in rows]) if x_key else [None]
    lines = _order([r["settings"].get(line_key) for r in rows]) if line_key else [None]
    numeric = all(isinstance(v, int | float) for v in xs) and x_key is not None
    for line in lines:
        med, ok = [], []
        for x in xs:
            rs = [r for r in rows if (x_key is None or r["settings"].get(x_key) == x)
                  and (line_key is None or r["settings"].get(line_key) == line)]
            med.append(float(np.median([r["error_mm"] for r in rs])) if rs else np.nan)
            ok.append(float(np.mean([r["success"] for r in rs])) * 100 if rs else np.nan)
        pos = xs if numeric else list(range(len(xs)))
        label = f"{line_key}={line}" if line_key else None
        axes[0].plot(pos, np.maximum(med, 1e-6), marker="o", label=label)
        axes[1].plot(pos, ok, marker="o", label=label)
    for ax, name in zip(axes, ("median best error (mm)", "success (%)"), strict=True):
        ax.set_title(name, fontsize=9)
        ax.set_xlabel(x_key or "")
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(x) for x in xs])
        ax.grid(alpha=0.3)
        if line_key:
            ax.legend(fontsize=7)
    axes[0].set_yscale("log")
    fig.suptitle(f"sweep {clip(title, 80)} ({len(rows)} jobs; over seeds)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def _csv(value) -> str:
    text = str(value)
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if any(c in text for c in ',"\n') else text
