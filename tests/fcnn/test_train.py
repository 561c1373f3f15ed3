"""The learning procedure: expert creation, convergence on a tiny chain, determinism, resume."""

from __future__ import annotations

import pytest
import torch

from graspnet_torch.fcnn.experts import ExpertSetCfg
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.fcnn.reach import ReachCfg
from graspnet_torch.fcnn.train import FCNNTrainCfg, FingerTrainer

TINY = dict(targets_per_epoch=64, train_steps=20, batch_size=64, val_targets=500, random_restarts=8,
            random_rounds=3)


def test_new_expert_when_target_out_of_every_experts_reach(index_chain):
    """Steps 1-3 all fail (the only expert outputs, and represents, the singular straight finger),
    so step 4 finds a random start that works and founds a second expert on its end posture."""
    trainer = FingerTrainer(index_chain, FCNNTrainCfg(**TINY), seed=3)
    with torch.no_grad():  # make expert 0 answer the straight finger for every target
        for p in (trainer.experts.W3, trainer.experts.b3):
            p.zero_()
        trainer.experts.b3[0] = trainer.experts.normalize_q(torch.zeros(4))
    target = trainer.kernel.position(torch.tensor([[0.1, 0.8, 0.9, 0.4]]))
    stats = {k: 0 for k in ("points", "motions", "step1", "step2", "step3", "step4", "unsolved", "new_experts")}
    trainer.collect(target, stats)
    assert (stats["step1"], stats["step2"], stats["step3"]) == (0, 0, 0)
    assert stats["step4"] == 1 and stats["new_experts"] == 1
    assert trainer.experts.n_active == 2
    assert trainer.data.counts(2).tolist() == [0, stats["points"]]  # its motion belongs to the new expert
    rep = trainer.experts.rep_postures[1]
    assert float((trainer.kernel.position(rep) - target[0]).norm()) < trainer.cfg.reach.r_e


@pytest.mark.slow
def test_tiny_training_on_planar_2r_chain_converges(hand, planar_chain):
    cfg = FCNNTrainCfg(experts=ExpertSetCfg(hidden=35, max_experts=4), reach=ReachCfg(), epochs=40,
                       **{**TINY, "train_steps": 40})
    trainer = FingerTrainer(planar_chain, cfg, seed=0)
    first = trainer.validate()
    for _ in range(cfg.epochs):
        trainer.epoch()
    last = trainer.validate()
    assert last["median_mm"] < 0.25 * first["median_mm"]
    assert last["median_mm"] < 3.0
    # refinement of the competition's answer converges on this well-conditioned chain
    from graspnet_torch.robot.ik import refine

    out, _errs, win = trainer.compete(trainer.val_x)
    q0 = out.gather(0, win.view(1, -1, 1).expand(1, -1, 2)).squeeze(0)
    _, refined = refine(trainer.kernel.position_jacobian, q0, trainer.val_x, trainer.lower, trainer.upper, 3)
    assert float(refined.median()) < 1e-5


@pytest.mark.slow
def test_same_seed_same_experts(index_chain):
    cfg = FCNNTrainCfg(epochs=3, **TINY)
    a, b = FingerTrainer(index_chain, cfg, seed=5), FingerTrainer(index_chain, cfg, seed=5)
    for _ in range(3):
        a.epoch()
        b.epoch()
    for (na, pa), (_, pb) in zip(a.experts.state_dict().items(), b.experts.state_dict().items(), strict=True):
        assert torch.equal(pa, pb), na


@pytest.mark.slow
def test_state_round_trip_continues_identically(index_chain):
    cfg = FCNNTrainCfg(epochs=6, reassign_every=2, **TINY)
    straight = FingerTrainer(index_chain, cfg, seed=1)
    for _ in range(6):
        straight.epoch()
    first = FingerTrainer(index_chain, cfg, seed=1)
    for _ in range(3):
        first.epoch()
    resumed = FingerTrainer(index_chain, cfg, seed=1)
    resumed.load_state_dict(first.state_dict())
    for _ in range(3):
        resumed.epoch()
    assert resumed.epochs_done == 6 and len(resumed.data) == len(straight.data)
    for key, value in straight.experts.state_dict().items():
        assert torch.allclose(resumed.experts.state_dict()[key], value, atol=1e-6), key


@pytest.mark.slow
def test_trained_set_drives_finger_ik(hand, index_chain):
    trainer = FingerTrainer(index_chain, FCNNTrainCfg(epochs=5, **TINY), seed=0)
    for _ in range(5):
        trainer.epoch()
    ik = FingerIK(hand, {"index": trainer.experts})
    _q, err = ik.solve("index", trainer.val_x)
    _out, errs, win = trainer.compete(trainer.val_x)
    assert torch.allclose(err, errs.gather(0, win.unsqueeze(0)).squeeze(0), atol=1e-6)
