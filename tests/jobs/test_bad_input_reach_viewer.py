"""Reach settings, the documented command lines and the viewer, as a careless or hostile user gives
them: the documented override syntax works as written, a motion's size is bounded by what it
produces, and every bad viewer input is one line, exit 2, before any server starts."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.io import json_digest
from graspnet_torch.jobs.cli import check_overrides, compose_for_check, hydra_overrides, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import (
    InspectRobotsJobCfg,
    ReferencePostureJobCfg,
    SolveGraspJobCfg,
    TrainFCNNJobCfg,
    TrainPostureJobCfg,
)
from graspnet_torch.jobs.interrupt import interrupted, stop_if_interrupted
from graspnet_torch.jobs.reproduce import ReproduceJobCfg
from graspnet_torch.jobs.solve_grasp import job_settings
from graspnet_torch.jobs.synthesize import SynthesizeGraspsJobCfg
from graspnet_torch.motion.config import ReachCfg
from graspnet_torch.motion.trajectory import TooManyRows, time_path
from graspnet_torch.paths import repo_root
from graspnet_torch.viz.viewer import load_view
from tests.in_process import run_script
from tests.refusals import check_refusal, interrupted_command, refused

SCRIPTS = {"solve_grasp": SolveGraspJobCfg, "train_fcnn": TrainFCNNJobCfg, "train_posture": TrainPostureJobCfg,
           "reproduce": ReproduceJobCfg, "reference_posture": ReferencePostureJobCfg,
           "inspect_robots": InspectRobotsJobCfg, "synthesize_grasps": SynthesizeGraspsJobCfg}


# ------------------------------------------------------------------ reach settings
@pytest.mark.parametrize("args", [["reach=true", "reach.timeout_s=10"], ["reach.timeout_s=10", "reach=true"],
                                  ["reach=true", "+reach.timeout_s=10"]])
def test_the_documented_reach_override_switches_the_motion_on_with_its_setting(args):
    argv = hydra_overrides(["task=cube", *args], SolveGraspJobCfg)
    check_overrides(argv, SolveGraspJobCfg)
    [(cfg, _)] = compose_for_check("solve_grasp", argv)
    job = job_settings(cfg)[0]
    assert job.reach == ReachCfg(enabled=True, timeout_s=10.0)


def test_reach_off_by_default_and_bad_reach_values_are_refused(tmp_path):
    [(cfg, _)] = compose_for_check("solve_grasp", hydra_overrides(["task=cube"], SolveGraspJobCfg))
    assert job_settings(cfg)[0].reach == ReachCfg()
    refused(tmp_path, "solve_grasp.py", "task=cube", "reach=maybe",
            message="reach.enabled='maybe': expected true or false")
    refused(tmp_path, "solve_grasp.py", "task=cube", "reach=true", "reach.max_samples=1",
            message="reach.max_samples=1: expected an integer in [2, 200000]")
    refused(tmp_path, "solve_grasp.py", "-m", "task=cube", "--cfg", "job", message="-m (a sweep) cannot be combined")


def _documented_commands() -> list[tuple[str, list[str]]]:
    """Every ``python scripts/X.py ARGS`` of the README, the docs, the scripts' and configs' own
    comments and the examples, for the Hydra scripts, with
    optional ``[key=value]`` parts taken as given; placeholders (``<...>``, ``{...}``, ``NAME``)
    skipped."""
    out = set()
    root = repo_root()
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md")), *sorted((root / "scripts").glob("*.py")),
             *sorted((root / "configs").glob("*.yaml")), *sorted((root / "examples").rglob("*.md")),
             *sorted((root / "examples").rglob("*.yaml"))]
    for page in pages:
        text = page.read_text().replace("\\\n", " ")
        for m in re.finditer(r"python scripts/(\w+)\.py([^\n`#|]*)", text):
            script, rest = m.group(1), m.group(2)
            if script not in SCRIPTS or re.search(r"[<{]|=NAME\b", rest):
                continue
            args = []
            for token in rest.split():
                optional = re.fullmatch(r"\[([\w.+~/]+=.*)\]", token)  # [key=value]: an optional setting
                token = optional.group(1) if optional else token
                if token != "-m" and not re.fullmatch(r"[+~]*[\w./]+=[^\s]*", token):
                    break  # prose after the command
                args.append(token)
            out.add((script, tuple(args)))
    return sorted((s, list(a)) for s, a in out)


DOCUMENTED = _documented_commands()


def test_the_docs_show_many_command_lines():
    scripts = {s for s, _ in DOCUMENTED}
    assert len(DOCUMENTED) >= 40 and {"solve_grasp", "train_fcnn", "train_posture", "reproduce"} <= scripts
    assert ("solve_grasp", ["task=cube", "reach=true", "reach.timeout_s=10"]) in DOCUMENTED


@pytest.mark.parametrize(("script", "args"), DOCUMENTED, ids=[" ".join([s, *a])[:80] for s, a in DOCUMENTED])
def test_every_documented_command_line_passes_the_parser_and_composes(script, args):
    """The overrides of each documented command, through the same checks and Hydra composition the
    script runs before its job (a sweep: each of its jobs)."""
    schema = SCRIPTS[script]
    argv = hydra_overrides(args, schema)
    check_overrides(argv, schema)
    jobs = compose_for_check(script, argv)
    assert jobs, f"nothing composed for {script} {args}"


# ------------------------------------------------------------------ a motion's size
def test_a_motion_with_too_many_rows_is_refused_before_any_row_is_made():
    corners = np.array([[0.0, 0.0], [1.0, -1.0]])
    times, rows, _ = time_path(corners, np.array([2.0, 2.0]), np.array([4.0, 4.0]), 50.0, max_rows=1000)
    assert len(rows) == len(times) and np.allclose(rows[-1], corners[-1])
    with pytest.raises(TooManyRows) as info:  # 1e-6 rad/s^2: 2,000 s rest to rest, 100 million rows at 50 kHz
        time_path(corners, np.array([2.0, 2.0]), np.array([1e-6, 1e-6]), 50_000.0, max_rows=100_000)
    assert info.value.rows > 10**8 and info.value.duration == pytest.approx(2000.0, rel=1e-3)


def test_a_slow_motion_is_reported_missing_with_the_settings_named():
    problem = gt.GraspProblem.from_task("cube")
    result = gt.solve(problem, trials=2, seed=0)
    t0 = time.perf_counter()
    motion = gt.plan_reach(problem, result, ReachCfg(enabled=True, acceleration=1e-6, sample_hz=10_000.0))
    assert not motion.found and len(motion.times) == 0 and time.perf_counter() - t0 < 30
    assert "reach.max_samples=100000" in motion.reason and "reach.acceleration" in motion.reason


# ------------------------------------------------------------------ the viewer
@pytest.fixture(scope="module")
def glass3_result(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("viewer")
    data = gt.solve("glass3", trials=2, seed=0).to_dict()
    data["problem"] = "glass3"
    (folder / "result.json").write_text(json.dumps(data))
    return folder / "result.json"


def _viewer_refused(tmp_path: Path, *args: str, message: str) -> str:
    res = run_script("view.py", *args)
    return check_refusal(tmp_path, res.returncode, res.stderr, message)


@pytest.mark.parametrize(("trials", "message"), [
    ([1, 2], "trials[0] is not a trial"),
    ([{"palm_pose": "x", "joints": 3}], "a trial does not fit robot 'hand'"),
    ([{"palm_pose": [0, 0, 0, 0, 0, 0], "joints": {"index": "abc"}}], "a trial does not fit robot 'hand'"),
])
def test_a_result_whose_trials_are_garbage_is_refused(tmp_path, glass3_result, trials, message):
    data = json.loads(glass3_result.read_text())
    data["trials"] = trials
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    _viewer_refused(tmp_path, str(path), message=message)


@pytest.mark.parametrize(("args", "message"), [
    (["--port", "\u00b2"], "--port: '\u00b2' is not a port (1-65535)"),
    (["--port", "0"], "is not a port"),
    (["--host", "999.999.1.1"], "--host: '999.999.1.1' is not an IP address"),
    (["--host", "my-laptop.example"], "is not an IP address"),
    (["--host", "192.0.2.77"], "not an address of this machine"),  # TEST-NET-1: never this machine's
    (["--frobnicate"], "unrecognized arguments"),
])
def test_bad_viewer_settings_are_refused_at_once(tmp_path, glass3_result, args, message):
    t0 = time.perf_counter()
    _viewer_refused(tmp_path, str(glass3_result), *args, message=message)
    assert time.perf_counter() - t0 < 10


def test_a_replay_of_another_problem_or_run_is_refused(tmp_path, glass3_result):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "result.json").write_text(glass3_result.read_text())
    trials = json.loads(glass3_result.read_text())["trials"]
    rows = [[{k: v for k, v in t.items() if k != "trials"} for t in trials]]
    for replay in ({"problem": "glass4", "result": json_digest(trials), "iterations": [1], "trials": rows},
                   {"problem": "glass3", "result": "0123456789abcdef", "iterations": [1], "trials": rows},
                   {"problem": "glass3", "iterations": [1], "trials": rows}):  # same count, not this result
        (folder / "replay.json").write_text(json.dumps(replay))
        _viewer_refused(tmp_path / "x", str(folder), message="not the replay of this result")
    (folder / "replay.json").write_text(json.dumps({"problem": "glass3", "result": json_digest(trials),
                                                    "iterations": [1], "trials": rows}))
    assert load_view(folder).replay is not None  # its own replay is served


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _terminal_sigint() -> None:
    """In the child: Ctrl-C as a terminal's command gets it (default disposition, not blocked),
    whatever the test process's own (a test run's worker has been seen with SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _serve(args: list[str]) -> subprocess.Popen:
    args = [*args, "--port", str(_free_port())]
    proc = subprocess.Popen([sys.executable, str(repo_root() / "scripts" / "view.py"), *args], text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_terminal_sigint)
    for line in proc.stdout:  # viser's banner, then "viewing ... at http://...": the page is served
        if line.startswith("viewing "):
            return proc
    raise AssertionError(proc.stderr.read())


def test_serving_other_machines_is_said_and_ctrl_c_stops_in_one_line(glass3_result):
    proc = _serve([str(glass3_result), "--host", "0.0.0.0"])
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    lines = err.strip().splitlines()
    assert proc.returncode == 0 and "Traceback" not in err, err[-2000:]
    assert lines[0].startswith("warning: serving on 0.0.0.0: other machines") and lines[1:] == ["stopped (Ctrl-C)"]
    local = _serve([str(glass3_result)])  # the default: this machine only, no warning
    local.send_signal(signal.SIGINT)
    _, err = local.communicate(timeout=60)
    assert local.returncode == 0 and err.strip() == "stopped (Ctrl-C)", err[-2000:]


def test_a_result_with_its_reach_motion_is_viewed_and_a_foreign_motion_refused(tmp_path):
    problem = gt.GraspProblem.from_task("cube")
    result = gt.solve(problem, trials=4, seed=0)  # its motion is found in about a second
    result.trajectory = gt.plan_reach(problem, result, ReachCfg(enabled=True, timeout_s=60.0))  # found in ~1 s idle
    assert result.trajectory.found
    data = result.to_dict()
    data["problem"] = "cube"
    (tmp_path / "result.json").write_text(json.dumps(data))
    motion = load_view(tmp_path).motion
    assert motion is not None and np.allclose(motion.positions, result.trajectory.positions, atol=1e-9)
    data["trajectory"]["joint_names"] = data["trajectory"]["joint_names"][::-1]
    (tmp_path / "other.json").write_text(json.dumps(data))
    _viewer_refused(tmp_path, str(tmp_path / "other.json"), message="the trajectory's joint_names are not the planned")


def test_ctrl_c_while_hydra_composes_the_run_is_one_line(capsys):
    """Ctrl-C after the settings' checks but before the job starts (Hydra still composing the run,
    seconds on a busy machine): exit 130, one line, nothing written (as the subprocess test below
    sees when its Ctrl-C comes that early)."""

    def composing() -> None:  # a Hydra main interrupted before it hands over to the job
        raise KeyboardInterrupt

    with pytest.raises(SystemExit) as exit_info:
        run_cli(composing, SolveGraspJobCfg, argv=["task=glass3"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 130 and len(err.strip().splitlines()) == 1
    assert err.startswith("interrupted (Ctrl-C) before the job started"), err


def test_a_ctrl_c_that_a_library_turns_into_another_error_is_still_one_line(capsys):
    """Hydra's composition restores omegaconf flags in a ``finally``; a Ctrl-C landing there came
    out as an AttributeError with a traceback and exit 1 (a CI run). A real SIGINT is sent here
    inside such a block: the command still ends with the one interrupted line, exit 130."""

    def composing() -> None:
        try:
            signal.raise_signal(signal.SIGINT)
        finally:
            raise AttributeError("'NoneType' object has no attribute '_invalidate_flags_cache'")

    before = signal.getsignal(signal.SIGINT)  # pytest's own Ctrl-C
    with pytest.raises(SystemExit) as exit_info:
        run_cli(composing, SolveGraspJobCfg, argv=["task=glass3"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 130 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("interrupted (Ctrl-C) before the job started"), err
    assert signal.getsignal(signal.SIGINT) is before  # is back


def test_a_ctrl_c_that_a_library_swallows_before_the_job_still_stops_it(capsys):
    """pytorch_kinematics imports mujoco in ``try: ... except ImportError: pass``; a Ctrl-C during
    that import was lost and the solve ran on. The interrupt is remembered: the job never starts."""
    started = []

    @user_errors_exit_2
    def job() -> None:
        started.append(True)

    def composing() -> None:
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            pass  # as an optional import's ``except ImportError`` does to what the Ctrl-C became
        job()

    with pytest.raises(SystemExit) as exit_info:
        run_cli(composing, SolveGraspJobCfg, argv=["task=glass3"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 130 and err.startswith("interrupted (Ctrl-C) before the job started"), err
    assert started == []


def test_a_ctrl_c_that_a_library_swallows_in_the_job_stops_it_at_the_next_item(capsys):
    """trimesh imports its optional packages in ``try: ... except BaseException``; a Ctrl-C there was
    lost and a synthesis ran on through every object (exit 0). The job's loop now stops at its next
    item, one line, exit 130; and the next command starts with the interrupt forgotten."""
    done = []

    @user_errors_exit_2
    def job() -> None:
        for item in range(3):
            stop_if_interrupted()
            done.append(item)
            if item == 0:
                try:
                    signal.raise_signal(signal.SIGINT)
                except BaseException:
                    pass  # as trimesh's optional imports do

    with pytest.raises(SystemExit) as exit_info:
        run_cli(job, SolveGraspJobCfg, argv=["task=glass3"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 130 and done == [0], (done, err)
    assert err == "interrupted (Ctrl-C): files written before it are whole, the one being written is not there\n"
    assert not interrupted()
    stop_if_interrupted()  # outside a command: nothing to stop


def test_a_job_that_ran_on_past_a_swallowed_ctrl_c_still_exits_130(capsys):
    @user_errors_exit_2
    def job() -> None:
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            pass

    with pytest.raises(SystemExit) as exit_info:
        run_cli(job, SolveGraspJobCfg, argv=["task=glass3"])
    assert exit_info.value.code == 130 and capsys.readouterr().err.startswith("interrupted (Ctrl-C): files written")


def test_ctrl_c_in_a_solve_is_one_line_and_leaves_no_result(tmp_path):
    out, run = tmp_path / "result.json", tmp_path / "run"
    res = interrupted_command("solve_grasp.py", "task=glass3", "trials=200", "max_iterations=100000",
                              "solver.threshold=null", f"out={out}", f"hydra.run.dir={run}", ready=run, wait_s=1.0)
    assert res.returncode == 130 and "Traceback" not in res.stderr, res.stderr[-2000:]  # the search under way
    assert len(res.stderr.strip().splitlines()) == 1 and res.stderr.startswith("interrupted"), res.stderr
    assert not out.exists()


@pytest.mark.slow
def test_ctrl_c_in_a_parallel_sweep_says_its_finished_jobs_are_whole(tmp_path):
    """A terminal's Ctrl-C reaches the sweep and its joblib workers: each says what was written is
    whole; none says "nothing written" (its jobs had started)."""
    sweep = tmp_path / "sweep"
    res = interrupted_command("solve_grasp.py", "-m", "hydra/launcher=joblib", "task=glass3,glass4", "trials=200",
                              "max_iterations=100000", "solver.threshold=null", f"hydra.sweep.dir={sweep}",
                              ready=sweep / "1" / ".hydra", wait_s=1.0, group=True)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 130 and "Traceback" not in res.stderr and lines, res.stderr[-2000:]
    assert all(line == "interrupted (Ctrl-C): files written before it are whole, the one being written is not there"
               for line in lines), res.stderr[-2000:]
