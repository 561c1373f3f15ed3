"""The training job: outputs, TensorBoard, export, resume; the script's exit codes."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.fcnn import load_finger_ik
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.jobs.train_fcnn import train_fcnn
from graspnet_torch.paths import repo_root
from tests.in_process import run_script

TINY = FCNNTrainCfg(epochs=3, targets_per_epoch=32, train_steps=5, batch_size=32, val_targets=200, val_every=2)


@pytest.mark.slow
def test_job_writes_state_experts_tensorboard_and_export(hand, tmp_path, capsys):
    export = tmp_path / "exported" / "fcnn.pt"
    _ik, rows = train_fcnn(hand, TINY, tmp_path / "run", fingers=["index", "pinky"], export=export,
                          progress=False, eval_targets=300)
    out = capsys.readouterr().out
    for name in ("state.pt", "fcnn.pt"):
        assert (tmp_path / "run" / name).is_file()
    assert list((tmp_path / "run" / "tb").glob("events.out.tfevents.*"))
    assert [r["finger"] for r in rows] == ["index", "pinky"] and all(r["within_limits"] for r in rows)
    assert "median mm" in out and "pinky" in out
    loaded = load_finger_ik(hand, export)
    assert loaded.finger_names == ("index", "pinky")


@pytest.mark.slow
def test_resume_extends_an_interrupted_run(hand, tmp_path):
    run = tmp_path / "run"
    train_fcnn(hand, TINY, run, fingers=["middle"], progress=False, eval_targets=100)
    longer = FCNNTrainCfg(**{**TINY.__dict__, "epochs": 5})
    ik_resumed, _ = train_fcnn(hand, longer, run, fingers=["middle"], resume=True, progress=False, eval_targets=100)
    ik_straight, _ = train_fcnn(hand, longer, tmp_path / "straight", fingers=["middle"], progress=False,
                                eval_targets=100)
    a, b = ik_resumed.experts["middle"].state_dict(), ik_straight.experts["middle"].state_dict()
    for key in a:
        assert torch.allclose(a[key], b[key], atol=1e-6), key


def test_resume_with_changed_settings_is_refused(hand, tmp_path):
    train_fcnn(hand, TINY, tmp_path, fingers=["ring"], progress=False, eval_targets=100)
    changed = FCNNTrainCfg(**{**TINY.__dict__, "lr": 0.1})
    with pytest.raises(gt.ConfigError, match=r"different fcnn settings \(lr\)"):
        train_fcnn(hand, changed, tmp_path, fingers=["ring"], resume=True, progress=False)


def _script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(repo_root() / "scripts" / "train_fcnn.py"), *args],
                          capture_output=True, text=True, cwd=repo_root())


@pytest.mark.slow
def test_script_trains_and_refuses_bad_input(tmp_path):
    res = _script("robot=hand", "fingers=[thumb]", "fcnn.epochs=2", "fcnn.targets_per_epoch=16",
                  "fcnn.train_steps=2", "fcnn.val_targets=100", "eval_targets=100", "progress=false",
                  f"hydra.run.dir={tmp_path / 'ok'}")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "ok" / "fcnn.pt").is_file() and "thumb" in res.stdout
    res = run_script("train_fcnn.py", "robot=hand", "fingers=[little]", f"hydra.run.dir={tmp_path / 'bad'}")
    assert res.returncode == 2 and not (tmp_path / "bad").exists()
    assert res.stderr.strip().splitlines() == [
        "error: robot 'hand' has no finger 'little' (fingers: thumb, index, middle, ring, pinky)"]


@pytest.mark.slow
def test_interrupted_run_resumes_to_the_same_result(hand, tmp_path, monkeypatch):
    """Kill the run during the 2nd finger's 4th epoch; resume=true finishes it, and the experts
    equal those of an uninterrupted run (state is saved every checkpoint_every epochs)."""
    from graspnet_torch.fcnn import train as train_module

    cfg = FCNNTrainCfg(**{**TINY.__dict__, "epochs": 5})
    straight, _ = train_fcnn(hand, cfg, tmp_path / "straight", fingers=["thumb", "ring"], progress=False,
                             eval_targets=100)
    original = train_module.FingerTrainer.epoch
    calls = {"n": 0}

    def dying_epoch(self):
        calls["n"] += 1
        if calls["n"] == 5 + 4:  # thumb's 5 epochs, then ring's 4th
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(train_module.FingerTrainer, "epoch", dying_epoch)
    with pytest.raises(KeyboardInterrupt):
        train_fcnn(hand, cfg, tmp_path / "run", fingers=["thumb", "ring"], progress=False, checkpoint_every=2)
    assert (tmp_path / "run" / "state.pt").is_file() and not (tmp_path / "run" / "fcnn.pt").exists()
    monkeypatch.setattr(train_module.FingerTrainer, "epoch", original)
    resumed, _ = train_fcnn(hand, cfg, tmp_path / "run", fingers=["thumb", "ring"], resume=True, progress=False,
                            eval_targets=100, checkpoint_every=2)
    for finger in ("thumb", "ring"):
        a, b = resumed.experts[finger].state_dict(), straight.experts[finger].state_dict()
        for key in a:
            assert torch.allclose(a[key], b[key], atol=1e-6), (finger, key)
