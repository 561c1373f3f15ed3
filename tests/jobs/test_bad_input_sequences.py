"""Bad and odd input of many problems (a folder, a JSON-lines file, a sequence), of posture
proposal models, and Ctrl-C in a training.

- Names that map to the same result file each get their own file (``a``, ``a-2``, ...).
- An output folder holding a folder where a result goes, a hostile ``.jsonl`` line, a name that
  is not UTF-8: refused before any work, exit 2, one line naming the file or line, nothing written.
- A posture proposal model with nonsense sizes: refused on load, before Hydra's run folder, in
  one line, without allocating what it declares.
- Ctrl-C (SIGINT) in ``train_posture.py`` and ``train_fcnn.py``: exit 130, one line saying where
  the state is kept; resuming continues from it.
"""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
from pathlib import Path

import pytest
import torch
import yaml

from graspnet_torch.jobs.solve_many import load_problems
from graspnet_torch.paths import repo_root
from tests.in_process import run_script
from tests.refusals import interrupted_command, refused, refused_in_a_fresh_process

# two fingertips a hand reaches (the proposals land them at once: a solve of milliseconds)
PROBLEM = {"robot": "hand", "contacts": [{"finger": "thumb", "position": [0.07201, -0.00564, 0.105]},
                                         {"finger": "index", "position": [0.00909, -0.01004, 0.105]}]}
QUICK = ("trials=2", "max_iterations=20")


def _jsonl(path: Path, *lines: str) -> Path:
    path.write_text("".join(line + "\n" for line in lines))
    return path


def _named(name: str) -> str:
    return json.dumps({**PROBLEM, "name": name})


# ------------------------------------------------------------------ names that map to one file
def test_repeated_names_of_a_jsonl_file_each_get_their_own_result(tmp_path):
    """`a`, `a`, `a-2`: three frames, three result files (the repeat skips the name a later
    frame holds), summary.csv lists each under its file's name."""
    frames = _jsonl(tmp_path / "frames.jsonl", _named("a"), _named("a"), _named("a-2"))
    out = tmp_path / "out"
    res = run_script("solve_grasp.py", f"problem={frames}", "sequence=true", f"out={out}", *QUICK,
                     f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr[-2000:]
    assert sorted(p.name for p in out.iterdir()) == ["a-2.json", "a-3.json", "a.json", "summary.csv"]
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [(r["name"], r["problem"]) for r in rows] == [("a", "a"), ("a-3", "a"), ("a-2", "a-2")]
    assert json.loads((out / "a-2.json").read_text())["problem"] == "a-2"


def test_a_folder_whose_files_share_a_stem_gives_each_its_own_result(tmp_path):
    """a.yaml and a.json (and a-2.json beside them, and a name differing only in case): one
    result name each, never the same file, also on a file system that ignores case."""
    folder = tmp_path / "problems"
    folder.mkdir()
    for name in ("a.yaml", "a.json", "A-2.json", "b.yml"):
        (folder / name).write_text(json.dumps(PROBLEM))
    names = [name for name, _ in load_problems(folder)]
    assert names == ["A-2", "a", "a-3", "b"]
    assert len({n.casefold() for n in names}) == len(names)
    out = tmp_path / "out"
    res = run_script("solve_grasp.py", f"problem={folder}", f"out={out}", *QUICK, f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr[-2000:]
    assert sorted(p.name for p in out.iterdir()) == ["A-2.json", "a-3.json", "a.json", "b.json", "summary.csv"]
    assert len(list(csv.DictReader((out / "summary.csv").open()))) == 4


# ------------------------------------------------------------------ refused before any work
@pytest.mark.parametrize("taken", ["a-2.json", "summary.csv", "a.json"])
def test_a_folder_where_a_result_goes_is_refused_before_any_work(tmp_path, taken):
    frames = _jsonl(tmp_path / "frames.jsonl", _named("a"), _named("a"))
    out = tmp_path / "out"
    (out / taken).mkdir(parents=True)
    refused(tmp_path, "solve_grasp.py", f"problem={frames}", f"out={out}", *QUICK,
            message=f"out={out}: {taken} in it is a folder, where a result goes")
    assert [p.name for p in out.iterdir()] == [taken]  # no result written


def test_a_broken_link_where_a_result_goes_is_refused(tmp_path):
    frames = _jsonl(tmp_path / "frames.jsonl", _named("a"))
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.json").symlink_to(tmp_path / "nowhere")
    refused(tmp_path, "solve_grasp.py", f"problem={frames}", f"out={out}", *QUICK,
            message="a.json in it is not a regular file")
    assert [p.name for p in out.iterdir()] == ["a.json"]


HOSTILE_LINES = [
    ("[" * 200_000 + "]" * 200_000, ":2: nested too deeply"),
    ('{"robot": "hand", "name": ' + "9" * 5000 + "}", ":2: unreadable value (Exceeds the limit"),
    ('{"robot": "hand", "contacts": [{"finger": "thumb", "position": [' + "9" * 5000 + ", 0, 0]}]}",
     ":2: unreadable value (Exceeds the limit"),
    (_named("a\udcff"), ":2: 'name' is not UTF-8 text (a lone surrogate '\\udcff' at character 1)"),
    (json.dumps({**PROBLEM, "description": "x\ud800"}), ":2: 'description' is not UTF-8 text"),
]


@pytest.mark.parametrize(("line", "message"), HOSTILE_LINES, ids=["deep", "int-name", "int-position",
                                                                  "surrogate-name", "surrogate-description"])
def test_hostile_jsonl_lines_are_refused_naming_the_line(tmp_path, line, message):
    frames = _jsonl(tmp_path / "frames.jsonl", _named("first"), line)
    out = tmp_path / "out"
    refused(tmp_path, "solve_grasp.py", f"problem={frames}", "sequence=true", f"out={out}", *QUICK,
            message=f"{frames}{message}")
    assert not out.exists()


def test_a_line_that_is_not_utf8_is_refused_naming_the_line(tmp_path):
    frames = tmp_path / "frames.jsonl"
    frames.write_bytes(_named("ok").encode() + b"\n" + _named("cafX").encode().replace(b"cafX", b"caf\xe9") + b"\n")
    refused(tmp_path, "solve_grasp.py", f"problem={frames}", f"out={tmp_path / 'out'}", *QUICK,
            message=f"{frames}:2: not UTF-8 text (invalid byte at offset")
    assert not (tmp_path / "out").exists()


def test_a_problem_file_name_that_is_not_utf8_is_refused(tmp_path):
    folder = tmp_path / "problems"
    folder.mkdir()
    (folder / "good.yaml").write_text(json.dumps(PROBLEM))
    with open(os.fsencode(folder) + b"/caf\xe9.yaml", "w") as fh:
        fh.write(json.dumps(PROBLEM))
    refused(tmp_path, "solve_grasp.py", f"problem={folder}", f"out={tmp_path / 'out'}", *QUICK,
            message=f"{folder}: the file name caf\\xe9.yaml is not UTF-8")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_deeply_nested_line_is_refused_quickly_and_small_as_a_real_command(tmp_path):
    frames = _jsonl(tmp_path / "frames.jsonl", "[" * 200_000 + "]" * 200_000)
    refused_in_a_fresh_process(tmp_path, "solve_grasp.py", f"problem={frames}", f"out={tmp_path / 'out'}",
                               message=f"{frames}:1: nested too deeply", max_bytes=1 << 30)


# ------------------------------------------------------------------ posture proposal models
def _hand_copy(folder: Path, **changes) -> Path:
    """A copy of the hand as a robot config by path in ``folder``, its posture model beside it
    (the shipped one, with ``changes`` made to what it declares); a problem for it; its path."""
    folder.mkdir(parents=True, exist_ok=True)
    data = yaml.safe_load((repo_root() / "configs" / "robot" / "hand.yaml").read_text())
    data.update(name="hand_copy", urdf=str((repo_root() / data["urdf"]).resolve()),
                checkpoint=str((repo_root() / "checkpoints" / "hand" / "fcnn.pt").resolve()))
    (folder / "hand_copy.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    payload = torch.load(repo_root() / "checkpoints" / "hand" / "posture.pt", weights_only=True)
    payload["robot"] = "hand_copy"
    payload.update(changes)
    torch.save(payload, folder / "hand_copy.posture.pt")
    problem = folder / "p.yaml"
    problem.write_text(yaml.safe_dump({**PROBLEM, "robot": "hand_copy.yaml"}, sort_keys=False))
    return problem


BAD_SIZES = [
    ({"heads": -3}, "posture.heads=-3: expected an integer in [1, 256]"),
    ({"heads": 0}, "posture.heads=0: expected an integer in [1, 256]"),
    ({"hidden": [10**9, 256, 256]}, "posture.hidden[0]=1000000000: expected an integer in [1, 4096]"),
    ({"hidden": [4096, 4096, 4096]}, "tensors do not fit the recorded sizes (out.weight, trunk.0.bias"),
    ({"hidden": [256] * 10_000}, "tensors do not fit the recorded sizes (10000 hidden layers recorded, 3 in"),
    ({"slots": -1}, "slots=-1: expected an integer in [1, 10000]"),
    ({"n": 10**12}, "n=1000000000000: expected an integer in [1, 10000]"),
    ({"heads": "16"}, "posture.heads='16': expected an integer"),
]


@pytest.mark.parametrize(("changes", "message"), BAD_SIZES, ids=["negative-heads", "zero-heads", "huge-hidden",
                                                                  "hidden-not-held", "many-layers", "slots", "n",
                                                                  "text"])
def test_a_posture_model_with_nonsense_sizes_is_refused_before_the_run_folder(tmp_path, changes, message):
    problem = _hand_copy(tmp_path / "robot", **changes)
    line = refused(tmp_path, "solve_grasp.py", f"problem={problem}", f"out={tmp_path / 'r.json'}", *QUICK,
                   message=message)
    assert f"{tmp_path / 'robot' / 'hand_copy.posture.pt'}: a corrupted posture proposal checkpoint" in line \
        or "tensors do not fit" in line
    assert not (tmp_path / "r.json").exists()


def test_a_posture_model_with_nonsense_sizes_is_refused_for_many_problems_too(tmp_path):
    problem = _hand_copy(tmp_path / "robot", heads=0)
    frames = _jsonl(problem.parent / "frames.jsonl", json.dumps({**PROBLEM, "robot": "hand_copy.yaml"}))
    refused(tmp_path, "solve_grasp.py", f"problem={frames}", "sequence=true", f"out={tmp_path / 'out'}", *QUICK,
            message="posture.heads=0")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_huge_hidden_layer_is_refused_small_as_a_real_command(tmp_path):
    problem = _hand_copy(tmp_path / "robot", hidden=[4096, 4096, 4096])
    refused_in_a_fresh_process(tmp_path, "solve_grasp.py", f"problem={problem}", f"out={tmp_path / 'r.json'}",
                               *QUICK, message="tensors do not fit the recorded sizes", max_bytes=1 << 30)


# ------------------------------------------------------------------ Ctrl-C in a training
def _interrupt(tmp_path: Path, script: str, *args: str) -> tuple[subprocess.CompletedProcess, Path]:
    """``script ARGS`` as a real command, sent SIGINT once its training has written a state (it
    checkpoints every step); its outcome and run folder."""
    run = tmp_path / "train"
    res = interrupted_command(script, *args, "checkpoint_every=1", "progress=false", "export=false",
                              f"hydra.run.dir={run}", ready=run / "state.pt")
    return res, run


def _one_interrupted_line(res: subprocess.CompletedProcess, run: Path) -> str:
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 130, res.stderr[-2000:]
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert lines[0].startswith("interrupted: state ") and lines[0].endswith(
        f"kept in {run / 'state.pt'}; resume with the same command and resume=true"), lines[0]
    return lines[0]


TINY_POSTURE = ("posture.steps=1000000", "posture.samples=16", "posture.batch=16", "posture.hidden=[8]",
                "posture.heads=2", "posture.val_every=1000000", "eval_problems=1")
TINY_FCNN = ("fingers=[thumb]", "fcnn.targets_per_epoch=4", "fcnn.train_steps=1", "fcnn.batch_size=4",
             "fcnn.val_targets=4", "fcnn.val_every=1000000", "eval_targets=4")


@pytest.mark.slow
def test_ctrl_c_ends_a_posture_training_in_one_line_and_it_resumes(tmp_path):
    res, run = _interrupt(tmp_path, "train_posture.py", *TINY_POSTURE)
    line = _one_interrupted_line(res, run)
    step = int(re.search(r"state of step (\d+) of 1000000 kept", line).group(1))
    assert torch.load(run / "state.pt", weights_only=True)["trainer"]["steps_done"] == step
    again = run_script("train_posture.py", *TINY_POSTURE, f"posture.steps={step + 2}", "resume=true",
                       "checkpoint_every=1", "progress=false", "export=false", f"hydra.run.dir={run}")
    assert again.returncode == 0, again.stderr[-2000:]
    assert f"resuming {run / 'state.pt'} (step {step})" in again.stdout
    assert torch.load(run / "state.pt", weights_only=True)["trainer"]["steps_done"] == step + 2


@pytest.mark.slow
def test_ctrl_c_ends_an_fcnn_training_in_one_line_and_it_resumes(tmp_path):
    res, run = _interrupt(tmp_path, "train_fcnn.py", "fcnn.epochs=1000000", *TINY_FCNN)
    line = _one_interrupted_line(res, run)
    epoch = int(re.search(r"state at epoch (\d+) of 1000000 of finger 'thumb' kept", line).group(1))
    state = torch.load(run / "state.pt", weights_only=True)
    assert state["fingers"]["thumb"]["epochs_done"] == epoch and state["finished"] == []
    again = run_script("train_fcnn.py", f"fcnn.epochs={epoch + 2}", *TINY_FCNN, "resume=true", "checkpoint_every=1",
                       "progress=false", "export=false", f"hydra.run.dir={run}")
    assert again.returncode == 0, again.stderr[-2000:]
    assert f"resuming {run / 'state.pt'} (finished: none)" in again.stdout
    assert torch.load(run / "state.pt", weights_only=True)["finished"] == ["thumb"]
