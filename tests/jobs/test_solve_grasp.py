"""The main job's command line: outputs, exit statuses, refusals that write nothing."""

from __future__ import annotations

import json

import pytest

from graspnet_torch.errors import InternalError
from graspnet_torch.paths import repo_root
from graspnet_torch.tasks import random_sequence
from tests.in_process import ScriptRun, run_script


def _run(*args: str) -> ScriptRun:
    """scripts/solve_grasp.py's entry point, in this process (:func:`run_script`); the real command
    in a fresh process is tests/jobs/test_bad_input.py's test_valid_odd_input_runs."""
    return run_script("solve_grasp.py", *args)


@pytest.mark.slow
def test_task_run_writes_result_pictures_and_tensorboard(tmp_path):
    res = _run("task=glass3", "trials=4", "seed=0", "max_iterations=80", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    data = json.loads((tmp_path / "result.json").read_text())
    assert data["robot"] == "hand" and len(data["trials"]) == 4
    assert set(data["fingertip_error_mm"]) == {"thumb", "index", "middle"}
    for png in ("posture.png", "learning.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"
    assert list((tmp_path / "tb").glob("events.out.tfevents.*"))
    assert "trial" in res.stdout and "glass3" in res.stdout
    assert "trials succeeded (pads within 1 mm of their contacts and 30 degrees of the normals, no link over 1 mm " \
           "inside, collision-free)" in res.stdout


@pytest.mark.slow
def test_problem_file_with_out_and_noise(tmp_path):
    problem = tmp_path / "p.yaml"
    problem.write_text((repo_root() / "configs" / "task" / "glass3.yaml").read_text())
    out = tmp_path / "deep" / "result.json"
    res = _run(f"problem={problem}", f"out={out}", "trials=2", "max_iterations=30", "noise=sigma0.1",
               "pictures=false", "tensorboard=false", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr
    data = json.loads(out.read_text())
    assert data["settings"]["noise_sigma"] == 0.1 and data["settings"]["threshold"] is None
    assert all(t["iterations"] == 30 for t in data["trials"])
    assert "no stopping threshold: the trials ran their whole budget" in res.stdout


@pytest.mark.parametrize(("args", "message"), [
    (["task=bottle"], "unknown task 'bottle'"),
    (["noise=loud"], "unknown noise 'loud'"),
    (["robot=arm_hand"], "the problem is for robot 'hand', but robot=arm_hand was given"),
    (["trials=0"], "trials=0: expected an integer in [1, "),
    (["problem=/nonexistent/p.yaml"], "problem file not found"),
])
def test_refused_input_exits_2_with_one_line_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "result.json"
    res = _run(*args, f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], res.stderr
    assert not out.exists()
    assert not list(tmp_path.iterdir())  # not even the run folder


def test_bad_problem_file_exits_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: hand\ncontacts:\n  - {finger: index, position: [0, 0, 0]}\n"
                   "  - {finger: index, position: [0, 0, 1]}\n")
    res = _run(f"problem={bad}", f"out={tmp_path / 'r.json'}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"error: {bad}: contacts[1].finger: finger 'index' appears twice (contacts[0] and contacts[1])"]
    assert not (tmp_path / "r.json").exists()


def _job_cfg(out, **extra):
    return {"task": "glass3", "trials": 2, "max_iterations": 5, "out": str(out), "tensorboard": False,
            "pictures": False, "threads": 1, **extra}


def test_a_non_finite_result_is_an_internal_error_and_writes_nothing(tmp_path, monkeypatch, capsys):
    from graspnet_torch.jobs import solve_grasp as job
    from graspnet_torch.jobs.cli import user_errors_exit_2

    real_solve = job.solve

    def nan_solve(*args, **kwargs):
        result = real_solve(*args, **kwargs)
        result.trials[0].palm_pose[0] = float("nan")
        result.trials[1].palm_pose[0] = float("nan")
        return result

    monkeypatch.setattr(job, "solve", nan_solve)
    out = tmp_path / "r.json"
    with pytest.raises(InternalError, match=r"not finite .* in palm_pose\[0\]"):
        job.solve_grasp(_job_cfg(out), tmp_path)
    assert not out.exists() and not list(tmp_path.glob(".r.json*"))
    with pytest.raises(SystemExit) as info:
        user_errors_exit_2(lambda: job.solve_grasp(_job_cfg(out), tmp_path))()
    assert info.value.code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("internal error: ") and not out.exists()


def test_a_picture_failure_after_the_result_is_a_warning(tmp_path, monkeypatch, capsys):
    from graspnet_torch.jobs import solve_grasp as job

    def broken(*args, **kwargs):
        raise RuntimeError("no display\nsecond line")

    monkeypatch.setattr(job, "write_pictures", broken)
    out = tmp_path / "r.json"
    job.solve_grasp(_job_cfg(out, pictures=True), tmp_path)
    assert json.loads(out.read_text())["robot"] == "hand"
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: pictures not written: RuntimeError: no display second line"]


def test_the_robot_group_is_honoured(tmp_path):
    """An override of robot.palm_bounds changes the search space: every trial's palm pose lies in
    the narrowed bounds (a box around glass3's reference posture)."""
    from graspnet_torch.jobs import solve_grasp as job

    ref = [-0.0209, -0.0002, 0.2011, -19.43, 3.52, -80.42]
    lo = [v - d for v, d in zip(ref, (0.01, 0.01, 0.01, 5, 5, 5), strict=True)]
    hi = [v + d for v, d in zip(ref, (0.01, 0.01, 0.01, 5, 5, 5), strict=True)]
    import yaml

    from graspnet_torch.paths import configs_dir

    robot = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    robot["palm_bounds"] = {"min": lo, "max": hi}
    result = job.solve_grasp({**_job_cfg(tmp_path / "r.json"), "robot": robot, "max_iterations": 20}, tmp_path)
    for t in result.trials:
        assert all(a - 1e-6 <= v <= b + 1e-6 for v, a, b in zip(t.palm_pose, lo, hi, strict=True)), t.palm_pose
    wide = job.solve_grasp({**_job_cfg(tmp_path / "w.json"), "max_iterations": 20}, tmp_path)
    assert any(not all(a <= v <= b for v, a, b in zip(t.palm_pose, lo, hi, strict=True)) for t in wide.trials)


@pytest.mark.slow
def test_group_sweeps_run_every_job(tmp_path):
    res = _run("-m", "task=glass3,glass4", "trials=2", "max_iterations=5", "pictures=false", "tensorboard=false",
               f"hydra.sweep.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    robots = [json.loads((tmp_path / str(k) / "result.json").read_text())["problem"] for k in (0, 1)]
    assert robots == ["glass3", "glass4"]


@pytest.mark.slow
def test_arm_among_obstacles_from_the_command_line(tmp_path):
    """`robot=arm_hand task=env1 reward=r3` as INTERFACE.md: arm joints by name, palm pose, every
    finger, collisions; TensorBoard gets the collisions per iteration; the summary says how many
    trials are collision-free."""
    res = _run("robot=arm_hand", "task=env1", "reward=r3", "trials=4", "seed=0", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    data = json.loads((tmp_path / "result.json").read_text())
    assert data["robot"] == "arm_hand" and data["settings"]["reward"] == "r3"
    assert list(data["arm_joints"])[:2] == ["shoulder_flexion", "shoulder_abduction"]
    assert len(data["joints"]) == 5 and isinstance(data["collisions"], int)
    assert "collision-free (FCL" in res.stdout
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(tmp_path / "tb"))  # every event file in the folder (the run's and its hparams')
    events.Reload()
    assert "trial_00/collisions" in events.Tags()["scalars"]


@pytest.mark.slow
def test_the_free_hand_with_r3_keeps_its_fingers_out_of_the_glass():
    """glass3 with R3 (the demo): the object is the environment; far more trials end collision-free
    (FCL) than with R1, and the best posture is collision-free (measured: 18/20 against 5/20)."""
    import graspnet_torch as gt

    paper = gt.SolverCfg.paper()  # every trial to its own stop: the count compares the learners
    r1 = gt.solve("glass3", trials=20, seed=0, solver=paper, reward=gt.RewardCfg(kind="r1"))
    r3 = gt.solve("glass3", trials=20, seed=0, reward=gt.RewardCfg(kind="r3"), solver=paper)
    free1 = sum(t.collisions == 0 for t in r1.trials)
    free3 = sum(t.collisions == 0 for t in r3.trials)
    assert free3 >= 15 and free3 >= free1 + 8, (free1, free3)
    assert r3.best.collisions == 0 and r3.best.success and r3.best.total_error_mm < 1.0


@pytest.mark.slow
def test_manus_from_the_command_line(tmp_path):
    """`robot=manus task=cube`: the result JSON of INTERFACE.md (all 9 joints by name, d, alignment,
    gripper points, collisions) and a one-line summary."""
    res = _run("robot=manus", "task=cube", "trials=2", "seed=0", "max_iterations=50", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    data = json.loads((tmp_path / "result.json").read_text())
    assert data["robot"] == "manus" and len(data["arm_joints"]) == 9
    assert {"distance_mm", "alignment", "gripper_points", "collisions"} <= set(data)
    assert "best d " in res.stdout and (tmp_path / "posture.png").exists()


def test_a_missing_collision_mesh_is_refused_before_any_work(tmp_path):
    """With an object to collide with, every collision mesh must be found: exit 2, one line naming
    the link, no result written (robot given by path, no checkpoint needed to get there)."""
    import yaml

    from tests.mesh_robots import mesh_hand_urdf, write_robot

    robot = write_robot(tmp_path, mesh_hand_urdf('<mesh filename="meshes/missing_palm.stl"/>'))
    problem = tmp_path / "p.yaml"
    problem.write_text(yaml.safe_dump({
        "robot": "meshhand.yaml", "object": {"shape": "box", "size": [0.04, 0.04, 0.04], "pose": [0, 0, 0.1, 0, 0, 0]},
        "contacts": [{"finger": "thumb", "position": [0.02, 0, 0]}, {"finger": "index", "position": [-0.02, 0, 0]}]}))
    out = tmp_path / "r.json"
    res = _run(f"robot={robot}", f"problem={problem}", f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2, res.stderr
    assert "palm" in res.stderr and "missing_palm.stl" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_each_solver_from_the_command_line(tmp_path):
    """solver=dls and solver=cmaes: the same result JSON, pictures and TensorBoard as the default."""
    for name in ("dls", "cmaes"):
        run = tmp_path / name
        res = _run("task=glass3", "trials=3", "seed=0", f"solver={name}", "max_iterations=200", f"hydra.run.dir={run}")
        assert res.returncode == 0, res.stderr
        data = json.loads((run / "result.json").read_text())
        assert data["settings"]["solver"] == name and len(data["trials"]) == 3
        assert data["total_error_mm"] < 1.0
        assert (run / "learning.png").exists() and list((run / "tb").glob("events.out.tfevents.*"))


def test_dls_with_sensor_noise_is_refused_before_any_work(tmp_path):
    out = tmp_path / "r.json"
    res = _run("task=glass3", "solver=dls", "noise=sigma0.2", f"out={out}", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 2
    assert "solver=dls with noise.sigma=0.2" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not out.exists()


def _write_random_problems(robot, folder, n):
    import graspnet_torch as gt

    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for s in range(n):
        p = gt.random_reachable_problem(robot, s)
        rows.append({"robot": "hand", "contacts": [{"finger": c.finger, "position": [float(v) for v in c.position]}
                                                   for c in p.contacts]})
    return rows


@pytest.mark.slow
def test_many_problems_from_a_folder_write_one_result_each(hand, tmp_path):
    """problem=DIR: every problem file solved in one vectorised batch, one result JSON per file
    (named after it), a summary.csv, and the results checkable like any other."""
    folder = tmp_path / "problems"
    for k, data in enumerate(_write_random_problems(hand, folder, 3)):
        (folder / f"p{k}.json").write_text(json.dumps(data))
    out = tmp_path / "results"
    res = _run(f"problem={folder}", f"out={out}", "trials=2", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["p0.json", "p1.json", "p2.json", "summary.csv"]
    for k in range(3):
        data = json.loads((out / f"p{k}.json").read_text())
        assert data["total_error_mm"] < 1.0 and len(data["trials"]) == 2
    assert len((out / "summary.csv").read_text().splitlines()) == 4
    assert "3 problems" in res.stdout


def test_a_bad_line_of_a_jsonl_file_is_refused_before_any_work(hand, tmp_path):
    rows = _write_random_problems(hand, tmp_path, 2)
    path = tmp_path / "p.jsonl"
    path.write_text(json.dumps(rows[0]) + "\n\n" + '{"robot": "hand", "contacts": [}\n' + json.dumps(rows[1]) + "\n")
    out = tmp_path / "results"
    res = _run(f"problem={path}", f"out={out}", "trials=2", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2
    assert f"{path}:3: not valid JSON" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_sequence_of_frames_is_tracked_in_order_from_a_jsonl_file(hand, tmp_path):
    """problem=FRAMES.jsonl sequence=true: the lines in order, one result each; frames after the
    first land warm from the previous frame (one trial) and stay near it; summary.csv gives each
    frame's wall time."""
    import graspnet_torch as gt

    robot = gt.load_robot("hand")
    frames = random_sequence(robot, 3, 6, n_fingers=4)
    path = tmp_path / "frames.jsonl"
    path.write_text("".join(json.dumps(f.to_mapping()) + "\n" for f in frames))
    out = tmp_path / "results"
    res = _run(f"problem={path}", "sequence=true", "trials=4", f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr
    names = [f"line{k}" for k in range(1, 7)]
    assert sorted(p.stem for p in out.glob("*.json")) == sorted(names)
    data = [json.loads((out / f"{n}.json").read_text()) for n in names]
    assert all(d["total_error_mm"] < 1.0 for d in data)
    assert all(len(d["trials"]) == 1 for d in data[1:])  # warm: the previous frame's posture landed
    rows = (out / "summary.csv").read_text().splitlines()
    assert rows[0].split(",")[7] == "wall_time_s" and len(rows) == 7
    assert "landed warm" in res.stdout


def test_sequence_needs_frames(hand, tmp_path):
    res = _run("task=glass3", "sequence=true", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2 and "sequence=true solves the frames of a sequence" in res.stderr
    assert not (tmp_path / "run").exists()


def test_many_problems_refuse_a_file_as_out_and_a_zero_batch(hand, tmp_path):
    """problem=DIR writes into a folder: out naming a file, or batch=0, is refused before any work."""
    folder = tmp_path / "problems"
    for k, data in enumerate(_write_random_problems(hand, folder, 2)):
        (folder / f"p{k}.json").write_text(json.dumps(data))
    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    res = _run(f"problem={folder}", f"out={taken}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2 and "exists and is not a folder" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and taken.read_text() == "{}"
    res = _run(f"problem={folder}", "batch=0", f"out={tmp_path / 'out'}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2 and "batch=0" in res.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "run").exists()


def test_tensorboard_curves_read_back_equal_the_history(tmp_path):
    """Every logged point (each 10th iteration and the last) of every trial is the history's value."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    import graspnet_torch as gt
    from graspnet_torch.jobs.solve_grasp import log_tensorboard

    res = gt.solve("glass3", trials=3, seed=0, max_iterations=25, solver={"stop": None, "threshold": None})
    log_tensorboard(tmp_path, res, ("thumb", "index", "middle"), every=10)
    events = EventAccumulator(str(tmp_path), size_guidance={"scalars": 0})
    events.Reload()
    h = res.outcome.history
    for t in range(3):
        points = events.Scalars(f"trial_{t:02d}/total_error_mm")
        assert [p.step for p in points] == [1, 11, 21, 25]
        expected = [float(h["total"][k, t]) * 1000 for k in (0, 10, 20, 24)]
        assert [p.value for p in points] == pytest.approx(expected, rel=1e-6)
        index = events.Scalars(f"trial_{t:02d}/error_mm/index")
        assert index[-1].value == pytest.approx(float(h["errors"][24, t, 1]) * 1000, rel=1e-6)
        assert len(events.Scalars(f"trial_{t:02d}/sigma_mean")) == 4
