"""The posture training job: outputs, TensorBoard, export, resume; refusals with exit 2 and
nothing written."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.jobs.train_posture import train_posture
from graspnet_torch.proposal import PostureProposal, ProposalCfg, load_proposal
from graspnet_torch.proposal.train import ProposalTrainer
from graspnet_torch.solver import api
from graspnet_torch.solver.proposals import proposal_data
from tests.in_process import run_script

TINY = ProposalCfg(heads=4, hidden=(32, 32), samples=48, steps=6, batch=16, val_every=3)


@pytest.fixture(scope="module")
def hand_and_ik():
    return api.robot_and_ik("hand")


def test_the_job_writes_state_model_tensorboard_and_export(hand_and_ik, tmp_path, capsys):
    robot, ik = hand_and_ik
    export = tmp_path / "exported" / "posture.pt"
    model, table = train_posture(robot, ik, TINY, tmp_path / "run", export=export, progress=False, eval_problems=4)
    for name in ("state.pt", "posture.pt"):
        assert (tmp_path / "run" / name).is_file()
    assert list((tmp_path / "run" / "tb").glob("events.out.tfevents.*"))
    assert table["problems"] == 4 and "best of 4" in capsys.readouterr().out
    loaded = load_proposal(robot, export)
    t, m = torch.randn(2, 5, 3) * 0.05, torch.ones(2, 5)
    assert torch.equal(loaded(t, m)[0], model(t, m)[0])


def test_an_interrupted_run_resumed_gives_what_a_straight_run_gives(hand_and_ik):
    """The trainer's state (model, optimiser, step, batch generator) is everything: 6 steps,
    saved, loaded into a new trainer, 4 more equal 10 straight steps."""
    robot, ik = hand_and_ik
    data = proposal_data(robot, ik, 60, 0)
    train, held = data.split(48)
    cfg = replace(TINY, steps=10)

    def trainer() -> ProposalTrainer:
        torch.manual_seed(0)
        model = PostureProposal(5, 6, cfg)
        model.fit_scales(train.targets, train.mask, train.configs, torch.zeros(6, dtype=torch.bool))
        return ProposalTrainer(model, train, held, cfg, seed=0)

    straight, first = trainer(), trainer()
    for _ in range(10):
        straight.step()
    for _ in range(6):
        first.step()
    resumed = trainer()
    resumed.load_state_dict(first.state_dict())
    for _ in range(4):
        resumed.step()
    for key, value in resumed.model.state_dict().items():
        assert torch.equal(value, straight.model.state_dict()[key]), key


def test_the_job_resumes_where_its_state_stopped(hand_and_ik, tmp_path, capsys):
    robot, ik = hand_and_ik
    train_posture(robot, ik, TINY, tmp_path, progress=False, eval_problems=2)
    capsys.readouterr()
    train_posture(robot, ik, replace(TINY, steps=9), tmp_path, resume=True, progress=False, eval_problems=2)
    assert "(step 6)" in capsys.readouterr().out
    state = torch.load(tmp_path / "state.pt", weights_only=True)
    assert state["trainer"]["steps_done"] == 9


def test_resume_with_changed_settings_is_refused(hand_and_ik, tmp_path):
    robot, ik = hand_and_ik
    train_posture(robot, ik, TINY, tmp_path, progress=False, eval_problems=2)
    with pytest.raises(ConfigError, match=r"only posture\.steps and posture\.val_every may change"):
        train_posture(robot, ik, replace(TINY, heads=8), tmp_path, resume=True, progress=False, eval_problems=2)


@pytest.mark.parametrize(("args", "message"), [
    (["posture.heads=0"], "posture.heads=0: expected an integer in [1, 256]"),
    (["posture.lr=-1"], "posture.lr=-1: expected a number in (0, 1]"),
    (["robot=nope"], "nope"),
    (["export=/proc/x/posture.pt"], "export"),
])
def test_bad_input_is_refused_with_one_line_and_nothing_written(tmp_path, args, message):
    run = tmp_path / "run"
    res = run_script("train_posture.py", *args, f"hydra.run.dir={run}")
    assert res.returncode == 2, res.stderr
    lines = [line for line in res.stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], res.stderr
    assert not run.exists()
    assert gt  # the package imported: the refusal came from its own checks
