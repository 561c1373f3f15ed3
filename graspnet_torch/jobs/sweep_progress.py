"""A sweep's progress: one line per finished job with the time left, whatever the launcher.

A Hydra callback (``hydra.callbacks.progress`` in each script's config). Jobs of a joblib or
submitit sweep run in other processes, so the count lives in the sweep folder: the sweep writes
``.progress/start.json`` (its start time and number of jobs) and each job, as it ends, a marker
``.progress/<job number>``; the job that ends prints ``sweep: 3/8 jobs done, 12 s, about 20 s left``
on stderr. Quiet when stderr is not a terminal (a log file, a Slurm job), and for single runs.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback

from graspnet_torch.errors import say

__all__ = ["SweepProgress", "count_jobs"]


def count_jobs(overrides: list[str]) -> int | None:
    """The number of jobs the basic sweeper makes of these overrides (``a=1,2 b=x,y,z``: 6);
    None when it cannot tell (an interval sweep, for an optimising sweeper)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.core.override_parser.types import ChoiceSweep, Glob, IntervalSweep, RangeSweep

    n = 1
    for o in OverridesParser.create().parse_overrides(overrides):
        value = o.value()
        if isinstance(value, IntervalSweep | Glob):
            return None
        if isinstance(value, ChoiceSweep):
            n *= len(value.list)
        elif isinstance(value, RangeSweep):
            n *= len(list(o.sweep_iterator()))
    return n


def _folder(config: Any) -> Path:
    return Path(str(config.hydra.sweep.dir)) / ".progress"


class SweepProgress(Callback):
    """Hydra callback: writes the sweep's start, counts finished jobs, prints the time left."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled

    def on_multirun_start(self, config: Any, **kwargs: Any) -> None:
        if not self.enabled:
            return
        folder = _folder(config)
        folder.mkdir(parents=True, exist_ok=True)
        try:
            total = count_jobs(list(config.hydra.overrides.task))
        except Exception:  # a sweep Hydra accepted but this count does not understand: no total
            total = None
        (folder / "start.json").write_text(json.dumps({"start": time.time(), "total": total}))

    def on_job_end(self, config: Any, job_return: Any, **kwargs: Any) -> None:
        from hydra.types import RunMode

        if not self.enabled or config.hydra.mode != RunMode.MULTIRUN:
            return
        folder = _folder(config)
        try:
            start = json.loads((folder / "start.json").read_text())
            (folder / str(config.hydra.job.num)).touch()
            done = sum(1 for p in folder.iterdir() if p.name.isdigit())
        except (OSError, ValueError):
            return  # a job launched elsewhere (a cluster without this folder): nothing to count
        if sys.stderr.isatty():
            say(progress_line(done, start.get("total"), time.time() - start["start"]))


def progress_line(done: int, total: int | None, elapsed: float) -> str:
    """``sweep: 3/8 jobs done, 12 s, about 20 s left``."""
    if not total:
        return f"sweep: {done} jobs done, {elapsed:.0f} s"
    left = elapsed / max(done, 1) * max(total - done, 0)
    return f"sweep: {done}/{total} jobs done, {_duration(elapsed)}, about {_duration(left)} left"


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{math.ceil(seconds):.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
