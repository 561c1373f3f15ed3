"""The sweep progress callback: its job count, its estimate, and its quiet mode."""

from __future__ import annotations

import io

from hydra.types import RunMode
from omegaconf import OmegaConf

from graspnet_torch.jobs.sweep_progress import SweepProgress, count_jobs, progress_line


def test_the_job_count_is_the_product_of_the_sweeps():
    assert count_jobs(["noise=none,sigma0.05,sigma0.1,sigma0.2", "seed=0,1", "trials=4"]) == 8
    assert count_jobs(["seed=range(0,5)", "reward.a=1,20"]) == 10
    assert count_jobs(["seed=0"]) == 1
    assert count_jobs(["reward.a=interval(1,20)"]) is None


def test_the_estimate_of_the_time_left():
    assert progress_line(2, 8, 10.0) == "sweep: 2/8 jobs done, 10 s, about 30 s left"
    assert progress_line(8, 8, 600.0) == "sweep: 8/8 jobs done, 10 min, about 0 s left"
    assert progress_line(3, None, 5.0) == "sweep: 3 jobs done, 5 s"


class _Terminal(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty


def _config(sweep, num: int, mode=RunMode.MULTIRUN):
    return OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}, "mode": mode, "job": {"num": num},
                                       "overrides": {"task": ["seed=0,1,2"]}}})


def test_each_finished_job_prints_the_count_on_a_terminal_only(tmp_path, monkeypatch):
    cb = SweepProgress()
    cb.on_multirun_start(_config(tmp_path, 0))
    lines = []
    for num, tty in ((0, True), (2, False), (1, True)):
        err = _Terminal(tty)
        monkeypatch.setattr("sys.stderr", err)
        cb.on_job_end(_config(tmp_path, num), job_return=None)
        lines.append(err.getvalue())
    assert lines[0].startswith("sweep: 1/3 jobs done") and lines[1] == "" and lines[2].startswith("sweep: 3/3 jobs")
    # a single run counts nothing
    err = _Terminal(True)
    monkeypatch.setattr("sys.stderr", err)
    cb.on_job_end(_config(tmp_path / "single", 0, RunMode.RUN), job_return=None)
    assert err.getvalue() == "" and not (tmp_path / "single").exists()
