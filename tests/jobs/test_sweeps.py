"""Sweeps: launchers that run real jobs, TensorBoard hparams, and the sweep summary."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from graspnet_torch.errors import ConfigError
from graspnet_torch.jobs.solve_grasp import hparams_of
from graspnet_torch.jobs.summarize_sweep import collect_sweep, summarize_sweep
from graspnet_torch.paths import repo_root
from graspnet_torch.solver.result import GraspResult, TrialResult
from tests.in_process import run_script


def _fake_sweep(root, rows):
    for k, (overrides, error, success) in enumerate(rows):
        job = root / str(k)
        (job / ".hydra").mkdir(parents=True)
        (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
        (job / "result.json").write_text(json.dumps({"robot": "hand", "success": success, "total_error_mm": error,
                                                     "iterations": 10 + k, "wall_time_s": 0.5, "collisions": 0}))


@pytest.mark.slow
def test_the_summary_tables_agree_with_the_job_results(tmp_path):
    """Swept parameters found from the overrides; per-setting medians recomputed by hand."""
    rows = [(["noise=none", "reward.a=1", f"seed={s}"], e, True) for s, e in enumerate((1.0, 3.0))]
    rows += [(["noise=sigma0.2", "reward.a=20", f"seed={s}"], e, s == 0) for s, e in enumerate((4.0, 10.0))]
    _fake_sweep(tmp_path, rows)
    swept, jobs = collect_sweep(tmp_path)
    assert swept == ["noise", "reward.a", "seed"] and len(jobs) == 4
    paths = summarize_sweep(tmp_path)
    csv = paths["csv"].read_text().splitlines()
    assert csv[0] == "job,noise,reward.a,seed,success,error_mm,iterations,wall_time_s,collisions"
    assert len(csv) == 5
    md = paths["md"].read_text()
    assert f"{np.median([4.0, 10.0]):.3g}" in md and "sigma0.2" in md
    line = next(t for t in md.splitlines() if t.startswith("| sigma0.2"))  # a markdown table's row
    assert [c.strip() for c in line.strip("|").split("|")][:4] == ["sigma0.2", "20", "2", "50"]  # 1 of 2 succeeded
    assert paths["png"].read_bytes()[:4] == b"\x89PNG"


def test_a_folder_without_results_is_refused_and_nothing_written(tmp_path):
    with pytest.raises(ConfigError, match="no job results"):
        summarize_sweep(tmp_path)
    res = run_script("summarize_sweep.py", str(tmp_path))
    assert res.returncode == 2 and res.stderr.startswith("error: ") and not list(tmp_path.iterdir())


def test_a_gripper_result_is_read_by_its_distance_and_a_foreign_file_refused(tmp_path):
    """Each environment names its ranked error's key: a MANUS job's distance_mm is its error; a
    result.json without one is refused with one line naming it, and no summary is written."""
    _fake_sweep(tmp_path, [(["seed=0"], 2.0, True)])
    job = tmp_path / "1"
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("- seed=1\n")
    (job / "result.json").write_text(json.dumps({"robot": "manus", "success": True, "distance_mm": 0.25}))
    _, jobs = collect_sweep(tmp_path)
    assert [j["error_mm"] for j in jobs] == [2.0, 0.25]
    (job / "result.json").write_text(json.dumps({"robot": "manus", "success": True}))
    before = sorted(tmp_path.rglob("*"))
    with pytest.raises(ConfigError, match=r"1/result.json: not a grasp result \(no total_error_mm or distance_mm\)"):
        summarize_sweep(tmp_path)
    assert sorted(tmp_path.rglob("*")) == before


def test_hparams_are_the_overrides_over_the_settings():
    trial = TrialResult(success=True, iterations=7, reinforcement=0.99, wall_time_s=0.2, total_error_mm=0.5)
    result = GraspResult(robot="hand", trials=[trial], seed=3, settings={"solver": "srv", "noise_sigma": 0.2,
                                                                         "reward_a": 20.0, "trials": 1})
    hp, metrics = hparams_of(result, ["noise=sigma0.2", "reward.a=20", "seed=3", "hydra.run.dir=x", "+foo=1.5"])
    assert hp["noise"] == "sigma0.2" and hp["reward.a"] == 20 and hp["foo"] == 1.5 and hp["solver"] == "srv"
    assert "hydra.run.dir" not in hp
    assert metrics == {"hparam/success": 1.0, "hparam/error_mm": 0.5, "hparam/iterations": 7.0,
                       "hparam/wall_time_s": 0.2, "hparam/collisions": 0.0}


def test_the_slurm_launcher_config_names_partition_time_cpus_and_array_parallelism():
    with initialize_config_dir(config_dir=str(repo_root() / "configs"), version_base=None):
        cfg = compose("solve_grasp", overrides=["hydra/launcher=slurm"], return_hydra_config=True)
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("SlurmLauncher")
    assert launcher.cpus_per_task == 1 and launcher.timeout_min == 60 and launcher.array_parallelism == 32
    assert "partition" in launcher


@pytest.mark.slow
def test_a_submitit_local_sweep_runs_real_jobs_and_summarizes(tmp_path):
    """hydra/launcher=submitit_local: real submitit jobs on this machine, each writing its result
    and its TensorBoard hparams; the summary turns them into the table."""
    sweep = tmp_path / "sweep"
    res = subprocess.run([sys.executable, str(repo_root() / "scripts" / "solve_grasp.py"), "-m",
                          "hydra/launcher=submitit_local", "task=glass3", "seed=0,1", "trials=2", "max_iterations=30",
                          "pictures=false", f"hydra.sweep.dir={sweep}"], capture_output=True, text=True,
                         cwd=repo_root())
    assert res.returncode == 0, res.stderr[-2000:]
    results = sorted(sweep.glob("*/result.json"))
    assert len(results) == 2
    assert {json.loads(p.read_text())["seed"] for p in results} == {0, 1}
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    tags = set()
    for events in (sweep / "0" / "tb").glob("events.out.tfevents.*"):
        acc = EventAccumulator(str(events))
        acc.Reload()
        tags |= set(acc.Tags()["scalars"])
    assert {"hparam/error_mm", "hparam/success"} <= tags
    swept, jobs = collect_sweep(sweep)
    assert swept == ["seed"] and len(jobs) == 2
    # the progress count crosses processes: the sweep's start and one marker per job that ended
    assert json.loads((sweep / ".progress" / "start.json").read_text())["total"] == 2
    assert sorted(p.name for p in (sweep / ".progress").iterdir() if p.name.isdigit()) == ["0", "1"]
