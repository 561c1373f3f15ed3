"""Bad and hostile input through the command line: each kind of mistake is refused with exit 2,
one line on stderr, no traceback and no file written (not even Hydra's run folder).

Each refusal runs the script's own entry point inside the test process (:func:`run_script`: the
same ``run_cli`` checks, milliseconds instead of a 3-5 s interpreter start); a sample of them also
runs as a real command in a fresh process, where its time and peak memory are measured."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from graspnet_torch.paths import repo_root
from tests.in_process import run_script
from tests.processes import run_measured
from tests.refusals import refused, refused_in_a_fresh_process, run_command, write_problem

GLASS3 = (repo_root() / "configs" / "task" / "glass3.yaml").read_text()
INDEX = "  - {finger: index, position: [0, 0, 0]}\n"


# ------------------------------------------------------------------ settings and overrides
@pytest.mark.parametrize(("args", "message"), [
    (["foo=1"], "unknown setting 'foo'"),
    (["+foo=1"], "unknown setting 'foo'"),
    (["solver.tolerance=1"], "unknown setting 'solver.tolerance' (settings of solver:"),
    (["noise.sigma=abc"], "noise.sigma='abc': expected a number in [0, 100]"),
    (["noise.sigma=-0.1"], "noise.sigma=-0.1: expected a number in [0, 100]"),
    (["solver.dtype=float7"], "solver.dtype='float7': expected one of float32, float64"),
    (["solver.report=worst"], "solver.report='worst': expected one of best, final"),
    (["solver.threshold=abc"], "solver.threshold='abc': expected a number in [-1, 2] or null"),
    (["threads=0"], "threads=0: expected an integer in [1, 1024]"),
    (["device=tpu9"], "device=tpu9: not a device"),
    (["seed=123456789012345678901234567890"], "seed=1234567890"),
    (["trials=abc"], "trials='abc': expected an integer"),
    (["trials=2.5"], "trials=2.5: expected an integer"),
    (["max_iterations=true"], "max_iterations=True: expected an integer"),
    (["srv.hidden=[20]"], "srv.hidden=[20]: expected a list of 2 values"),
    (["srv.lr_srv=1e308"], "srv.lr_srv=1e+308: expected a number in [0, 100]"),
    (["reward.a=0"], "reward.a=0: expected a number in (0, 10000]"),
    (["-m", "seed=0,1,abc"], "seed='abc'"),
    (["-m", "task=glass3,bottle"], "unknown task 'bottle'"),
    (["seed=${nope}"], "cannot resolve the settings"),
    (["trials=[1,"], "cannot parse the command line"),
    (["seed=" + "9" * 5000], "cannot parse the command line: Exceeds the limit"),
    (["out=/tmp/graspnet-no-such.d/"], "ends with '/': give a file path"),
    (["task=null"], "task=null: expected one of block5, cube, env1, env2, fig10, glass3"),
    (["--foo"], "unknown option '--foo'"),
    (["--cfg", "nonsense"], "argument --cfg/-c: invalid choice"),
    (["--config-name=train_fcnn"], "--config-name, --config-path and --config-dir are not supported"),
    (["-m", "seed=0,1", "problem=/dev/zero"], "/dev/zero: the problem file is not a regular file"),
    (["-m", "seed=0,1", "trials=200000000"], "trials=200000000 x max_iterations=2000 needs about"),
    (["srv.hidden=[4096,4096]"], "srv.hidden[0]=4096: expected an integer in [1, 1024]"),
    (["solver.stop=0"], "solver.stop=0: expected an integer in [1, 1000000]"),
    (["solver.gripper.approach_deg=-5"], "solver.gripper.approach_deg=-5: expected a number in (0, 360]"),
    (["solver.gripper.approach_m=abc"], "solver.gripper.approach_m='abc': expected a number"),
    (["solver.restart_every=0"], "solver.restart_every=0: expected an integer in [1, 10000000] or null"),
    (["solver.polish.min_gain=2"], "solver.polish.min_gain=2: expected a number in [0, 1]"),
    (["solver.polish.from_r_free=5"], "solver.polish.from_r_free=5: expected a number in [-1, 1] or null"),
    (["solver.polish.warm_step_deg=0"], "solver.polish.warm_step_deg=0: expected a number in (0, 360] or null"),
    (["solver.polish.centre=-1"], "solver.polish.centre=-1: expected a number in (0, 1000] or null"),
    (["solver.start=learned"], "solver.start='learned': expected one of auto, random, proposal"),
    (["sequence=maybe"], "sequence='maybe': expected true or false"),
    (["solver.polish_iterations=5"], "unknown setting 'solver.polish_iterations' (now solver.polish.iterations)"),
    (["reward=r5"], "unknown reward 'r5': expected one of default, r1, r2, r3, r4"),
    (["srv.lr_bp=null"], "srv.lr_bp=None: expected a number in [0, 100]"),
])
def test_bad_settings_are_refused_before_any_work(tmp_path, args, message):
    refused(tmp_path, "solve_grasp.py", *args, message=message)


def test_device_cuda_is_checked_for_availability(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    refused(tmp_path, "solve_grasp.py", "device=cuda", message="device=cuda: CUDA is not available")


@pytest.mark.slow
def test_sizes_that_cannot_fit_in_memory_are_refused_with_the_estimate(tmp_path):
    line = refused_in_a_fresh_process(tmp_path, "solve_grasp.py", "trials=200000000",
                                       message="trials=200000000 x max_iterations=2000")
    assert "GiB of memory but" in line and "solver.history=false" in line


# ------------------------------------------------------------------ problem files
@pytest.mark.parametrize(("text", "message"), [
    # an alias bomb in each checked field: refused before anything expands
    ("a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\nrobot: hand\ncontacts:\n"
     "  - {finger: *b, position: [0, 0, 0]}\n", "unknown key(s) a, b"),
    ("a: &a [x, x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
     "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
     "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e, *e]\n"
     "g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f, *f]\nh: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g, *g]\n"
     "i: &i [*h, *h, *h, *h, *h, *h, *h, *h, *h, *h]\nrobot: hand\ncontacts:\n  - {finger: *i, position: [0, 0, 0]}\n",
     "values through YAML aliases (*name); at most 100000 are allowed"),
    ("robot: hand\npalm_bounds: &p {min: [0, 0, 0, 0, 0, 0], max: [1, 1, 1, 1, 1, 1]}\nobstacles: [*p]\n"
     "contacts: []\n", "need 2 to 5 contacts"),
    ("robot: hand\ncontacts:\n  - {finger: thumb, position: [1.0e308, 0, 0]}\n" + INDEX,
     "contacts[0].position[0]: 1e+308 is not a finite number within [-10, 10]"),
    ("robot: hand\ncontacts:\n  - {finger: thumb, position: ['0.03', 0, 0]}\n" + INDEX,
     "contacts[0].position[0]: expected a number, got '0.03'"),
    ("robot: hand\ncontacts:\n  - {finger: thumb, position: [true, 0, 0]}\n" + INDEX,
     "contacts[0].position[0]: expected a number, got True"),
    ("robot: hand\nobject: {shape: box, size: [0.1, 0.1, 20], pose: [0, 0, 0, 0, 0, 0]}\ncontacts:\n"
     "  - {finger: thumb, position: [0, 0, 0]}\n  - {finger: index, position: [0, 0, 0]}\n",
     "object.size[2]: 20 is not a finite number within [-10, 10]"),
    (GLASS3.replace("reference:", "reference: 3\nignored:"), "unknown key(s) ignored"),
    (GLASS3.split("reference:")[0] + "reference: {palm_pose: [0, 0, 0, 0, 0, 0], joints: 3}\n",
     "reference.joints: expected a mapping finger -> joint angles"),
    ("robot: hand\ncontacts:\n  - {finger: [" + "x, " * 5000 + "x], position: [0, 0, 0]}\n"
     "  - {finger: index, position: [0, 0, 0]}\n", "unknown finger ['x', 'x', 'x', 'x', ...]"),
])
def test_bad_problem_files_are_refused_with_a_short_line(tmp_path, text, message):
    path = write_problem(tmp_path, text)
    line = refused(tmp_path, "solve_grasp.py", f"problem={path}", f"out={tmp_path / 'r.json'}", message=message)
    assert len(line) < 600


@pytest.mark.slow
def test_oversized_non_utf8_and_special_problem_files(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "w") as fh:
        fh.write("robot: hand\ncontacts: [")
        fh.write("0, " * 600_000)
        fh.write("0]\n")
    refused_in_a_fresh_process(tmp_path, "solve_grasp.py", f"problem={big}",
                                message="a problem file may have at most 1048576 bytes")
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(GLASS3.replace("Drinking glass", "Verre à boire").encode("latin-1"))
    refused(tmp_path, "solve_grasp.py", f"problem={latin}", message="not UTF-8 text")
    refused(tmp_path, "solve_grasp.py", "problem=/dev/zero", message="the problem file is not a regular file")
    # a folder is many problems: each file is checked, the first bad one named; an empty one is refused
    refused(tmp_path, "solve_grasp.py", f"problem={tmp_path}", message="big.yaml: 1800026 bytes")
    empty = tmp_path / "empty"
    empty.mkdir()
    refused(tmp_path, "solve_grasp.py", f"problem={empty}", message="no problem files (*.yaml, *.yml, *.json)")


# ------------------------------------------------------------------ paths
def test_mesh_paths_outside_the_allowed_folders_get_one_message_whether_or_not_they_exist(tmp_path):
    lines = []
    for mesh in ("/etc/passwd", "/etc/no-such-file.stl", "../../../../../../etc/passwd"):
        text = GLASS3.replace("shape: cylinder\n  size: [0.0325, 0.12]", f"shape: mesh\n  size: {mesh}")
        path = write_problem(tmp_path, text)
        line = refused(tmp_path, "solve_grasp.py", f"problem={path}", message="is outside the file's folder")
        lines.append(line.replace(mesh, "<mesh>"))
    assert len(set(lines)) == 1, lines


def test_a_file_inside_the_folder_must_be_a_real_mesh(tmp_path):
    (tmp_path / "cup.stl").write_text("this is not a mesh\n")
    text = GLASS3.replace("shape: cylinder\n  size: [0.0325, 0.12]", "shape: mesh\n  size: cup.stl")
    path = write_problem(tmp_path, text)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", message="cup.stl")


@pytest.mark.parametrize(("out", "message"), [
    ("/dev/null", "out=/dev/null: exists and is not a regular file"),
    ("{tmp}", "is a directory"),
    ("{tmp}/afile/result.json", "is not a folder"),
    ("/proc/graspnet-test/result.json", "cannot write in /proc"),
])
def test_out_must_be_a_regular_file_in_a_writable_folder(tmp_path, out, message):
    (tmp_path / "afile").write_text("x")
    out = out.format(tmp=tmp_path)
    refused(tmp_path, "solve_grasp.py", f"out={out}", message=message)
    assert (tmp_path / "afile").read_text() == "x"


# ------------------------------------------------------------------ training
@pytest.mark.parametrize(("args", "message"), [
    (["fcnn.epochs=-1"], "fcnn.epochs=-1: expected an integer in [1, "),
    (["fcnn.epochs=abc"], "fcnn.epochs='abc'"),
    (["fcnn.lr=abc"], "fcnn.lr='abc': expected a number in [0, 10]"),
    (["fcnn.optimizer=newton"], "fcnn.optimizer='newton': expected one of adam, sgd"),
    (["checkpoint_every=0"], "checkpoint_every=0: expected an integer"),
    (["fcnn.experts.hidden=0"], "fcnn.experts.hidden=0"),
    (["fingers=[little]"], "robot 'hand' has no finger 'little'"),
    (["export=/dev/null"], "export=/dev/null: exists and is not a regular file"),
    (["robot=octopus"], "unknown robot 'octopus'"),
])
def test_training_settings_are_refused_and_nothing_is_written(tmp_path, args, message):
    refused(tmp_path, "train_fcnn.py", *args, message=message)


def test_resume_from_a_non_finite_state_is_refused(tmp_path):
    import torch

    from graspnet_torch.jobs.train_fcnn import STATE_FORMAT

    run = tmp_path / "run"
    run.mkdir()
    state = {"format": STATE_FORMAT, "robot": "hand", "seed": 0, "cfg": {}, "fingerprints": {},
             "fingers": {"thumb": {"experts": {"W1": torch.full((2, 3), float("nan"))}}}, "finished": []}
    torch.save(state, run / "state.pt")
    res = run_script("train_fcnn.py", "resume=true", f"hydra.run.dir={run}")
    assert res.returncode == 2 and res.stderr.strip().splitlines() == [
        f"error: {run / 'state.pt'}: cannot resume, non-finite values (NaN or infinity) in thumb.experts.W1"]
    assert sorted(p.name for p in run.iterdir()) == ["state.pt"]  # checked before Hydra writes .hydra/


@pytest.mark.slow
def test_valid_odd_input_runs(tmp_path):
    """What looks odd but is valid runs: a sweep of good values, ints for floats, a JSON problem."""
    problem = tmp_path / "p.json"
    import yaml

    problem.write_text(json.dumps(yaml.safe_load(GLASS3)))
    res, _ = run_command("solve_grasp.py", f"problem={problem}", "trials=2", "max_iterations=5", "noise.sigma=0",
                  "reward.a=2", "pictures=false", "tensorboard=false", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr
    assert json.loads((tmp_path / "run" / "result.json").read_text())["settings"]["reward_a"] == 2.0
    assert os.listdir(tmp_path / "run")


@pytest.mark.slow
def test_memory_estimate_bounds_a_real_solve_from_above(tmp_path):
    """The peak memory of a real solve (4000 trials x 60 iterations with history, in a fresh
    process) stays under the estimate the refusal uses, and the estimate is not wildly above it."""
    from graspnet_torch.jobs.configs import estimate_solve_memory

    code = ("import torch, graspnet_torch as gt\n"
            "from graspnet_torch.solver.config import SolverCfg\n"
            "torch.set_num_threads(1)\n"
            "gt.solve('block5', trials=4000, solver=SolverCfg(max_iterations=60, threshold=None))\n")
    res, peak = run_measured([sys.executable, "-c", code], tmp_path / "peak.json", capture_output=True, text=True,
                             timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    estimate = estimate_solve_memory(4000, 60, 5)
    assert peak <= estimate < 3 * peak, (peak, estimate)


@pytest.mark.parametrize(("script", "args", "message"), [
    ("inspect_robots.py", ["robots=[octopus]"], "unknown robot 'octopus'"),
    ("inspect_robots.py", ["robots=abc"], "robots='abc': expected a list"),
    ("inspect_robots.py", ["out_dir=/dev/null"], "/dev/null is not a folder"),
    ("reference_posture.py", ["restarts=0"], "restarts=0: expected an integer in [1, 1000]"),
    ("reference_posture.py", ["task=bottle"], "unknown task 'bottle'"),
])
def test_the_other_scripts_refuse_bad_input_the_same_way(tmp_path, script, args, message):
    refused(tmp_path, script, *args, message=message)


@pytest.mark.parametrize(("args", "message"), [
    (["progress=false", "-m", "fcnn.epochs=1,2,abc"], "comes after an option: put options such as -m before"),
    (["fcnn.experts.hidden=4096"], "fcnn.experts.hidden=4096: expected an integer in [1, 1024]"),
    (["fcnn.val_targets=10000000"], "fcnn.val_targets=10000000: expected an integer in [1, 1000000]"),
    (["fcnn.targets_per_epoch=100000", "fcnn.random_restarts=1000"], "GiB of memory but"),
])
def test_training_sizes_beyond_reason_or_memory_are_refused(tmp_path, args, message):
    refused(tmp_path, "train_fcnn.py", *args, message=message)


@pytest.mark.parametrize(("bounds", "message"), [
    ("palm_bounds: robot\n", "the thumb contact lies 16.888 m from the palm's"),  # the robot's box
    ("", "the thumb and index contacts lie 17.147 m apart but those fingertips reach at most"),  # from the contacts
])
def test_a_contact_out_of_reach_is_refused_before_the_solve(tmp_path, bounds, message):
    text = f"robot: hand\n{bounds}contacts:\n  - {{finger: thumb, position: [9.9, 9.9, 9.9]}}\n" + INDEX
    path = write_problem(tmp_path, text)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", message=message)


ENV1 = (Path(__file__).resolve().parents[2] / "configs" / "task" / "env1.yaml").read_text()


@pytest.mark.parametrize(("text", "message"), [
    (ENV1.replace("obstacles:\n", "obstacles:\n  - {shape: cylinder, size: [0.05]}\n"),
     "obstacles[0].size: expected 2 numbers"),
    (ENV1.replace("obstacles:\n", "obstacles:\n  - {shape: torus, size: [0.05, 0.01]}\n"),
     "obstacles[0].shape: expected box, cylinder, sphere or mesh, got 'torus'"),
    (ENV1.replace("obstacles:\n", "obstacles:\n  - {shape: sphere, size: [0.05], pose: [0.4, -0.15, -0.2, 0, 0, 0]}\n"),
     "obstacles[0] (sphere) contains the thumb, index, middle contact"),
    (ENV1.replace("pose: [0.4, -0.15, -0.25, 0, 0, 180]", "pose: [3.0, -0.15, -0.25, 0, 0, 180]"),
     "the thumb contact lies 2.979 m from the arm's first joint but the arm and thumb reach at most 0.731 m"),
])
def test_bad_arm_problems_are_refused(tmp_path, text, message):
    """Malformed obstacles, an obstacle that swallows a contact and a contact beyond the arm's reach:
    exit 2, one line, nothing written."""
    path = write_problem(tmp_path, text)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", f"out={tmp_path / 'r.json'}", message=message)


CUBE = (Path(__file__).resolve().parents[2] / "configs" / "task" / "cube.yaml").read_text()


@pytest.mark.parametrize(("text", "message"), [
    (CUBE.replace("points: [[0.0, 0.035, 0.0], [0.0, -0.035, 0.0]]", "points: [[0.0, 0.035, 0.0]]"),
     "points: robot 'manus' needs exactly 2 object points"),
    (CUBE.replace("points: [[0.0, 0.035, 0.0], [0.0, -0.035, 0.0]]", "points: [[0, 0, 0], [0, 0, 0]]"),
     "the two points are at the same place"),
    (CUBE + "contacts: [{finger: thumb, position: [0, 0, 0]}]\n", "'contacts' (one point per finger) does not apply"),
    (CUBE + "approach: {base_z: 0.1}\n", "approach: unknown joint(s) base_z"),
    (CUBE + "approach: {elbow_pitch: 170}\n", "approach.elbow_pitch: 170 lies outside its limits [-150, 150] degrees"),
])
def test_bad_manus_problems_are_refused(tmp_path, text, message):
    path = write_problem(tmp_path, text)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", f"out={tmp_path / 'r.json'}", message=message)


@pytest.mark.parametrize(("script", "args", "message"), [
    ("train_fcnn.py", ["fcnn.targets_per_epoch=100000", "fcnn.random_restarts=1000"], "GiB of memory but"),
    ("inspect_robots.py", ["robots=[octopus]"], "unknown robot 'octopus'"),
    ("reference_posture.py", ["restarts=0"], "restarts=0: expected an integer in [1, 1000]"),
])
@pytest.mark.slow
def test_refusals_as_real_commands_are_quick_and_small(tmp_path, script, args, message):
    """A sample of the refusals above as real commands in a fresh process (solve_grasp.py's: the
    memory estimate and the oversized problem file above)."""
    refused_in_a_fresh_process(tmp_path, script, *args, message=message)


@pytest.mark.parametrize(("text", "args", "message"), [
    (ENV1 + "start: {elbow_twist: 10}\n", ["reach=true"], "start: unknown joint 'elbow_twist' of robot 'arm_hand'"),
    (ENV1 + "start: {elbow_flexion: 170}\n", ["reach=true"],
     "start.elbow_flexion: 170 lies outside its limits [0, 145"),
    (ENV1 + "start: {shoulder_flexion: 40, elbow_flexion: 60, shoulder_abduction: 20}\n", ["reach=true"],
     "start: the problem's start collides"),
    (ENV1 + "start: {elbow_flexion: x}\n", [], "start.elbow_flexion: expected a number"),
    (GLASS3 + "start: {index_mcp: 10}\n", ["reach=true"], "'start' (the configuration a reach motion starts from"),
    (ENV1, ["reach.timeout_s=0"], "reach.timeout_s=0"),
    (ENV1, ["reach=maybe"], "reach"),
])
def test_bad_reach_input_is_refused(tmp_path, text, args, message):
    """A reach motion's start with an unknown joint, outside its limits, colliding or malformed, a
    free hand's start, and bad reach settings: exit 2, one line, nothing written."""
    path = write_problem(tmp_path, text)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", f"out={tmp_path / 'r.json'}", *args, message=message)


@pytest.mark.parametrize(("switch", "message"), [
    ("reach=true", "reach=true plans the motion of one problem"),
    ("verify=physics", "verify=physics checks the result of one problem"),
])
def test_a_one_result_check_of_many_problems_is_refused(tmp_path, switch, message):
    folder = tmp_path / "problems"
    folder.mkdir()
    (folder / "a.yaml").write_text(ENV1)
    refused(tmp_path, "solve_grasp.py", f"problem={folder}", f"out={tmp_path / 'out'}", switch, message=message)
