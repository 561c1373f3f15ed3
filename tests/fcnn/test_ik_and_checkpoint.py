"""FingerIK inference, the shipped checkpoint's accuracy, checkpoint round trips and errors."""

from __future__ import annotations

import itertools

import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.fcnn import FingerIK, load_finger_ik
from graspnet_torch.fcnn.checkpoint import default_checkpoint, save_finger_ik
from graspnet_torch.fcnn.evaluate import heldout_targets
from graspnet_torch.paths import configs_dir
from graspnet_torch.robot import load_robot_cfg


@pytest.fixture(scope="module")
def ik(hand):
    return load_finger_ik(hand)


def test_shipped_checkpoint_covers_every_finger(ik, hand):
    assert default_checkpoint("hand").is_file()
    assert ik.finger_names == hand.finger_names
    assert all(4 <= ik.n_experts(f) <= 6 for f in ik.finger_names)


@pytest.mark.parametrize("finger", ["thumb", "index", "middle", "ring", "pinky"])
def test_shipped_checkpoint_accuracy_on_fresh_targets(ik, hand, finger):
    """Fresh targets (a seed used by neither training nor the closing table): competition alone
    median < 5 mm; with 3 refinement iterations >= 99.5 % within 1 mm, median < 0.05 mm; within
    joint limits."""
    _, x = heldout_targets(ik, finger, n=4000, seed=2024)
    q0, e0 = ik.solve(finger, x)
    q3, e3 = ik.solve(finger, x, refine=3)
    assert float(e0.median()) < 0.005
    assert float((e3 < 0.001).float().mean()) >= 0.995
    assert float(e3.median()) < 0.05e-3
    lo, hi = (torch.tensor(a, dtype=torch.float32) for a in hand.finger_limits)
    k = hand.finger_index(finger)
    for q in (q0, q3):
        assert bool(((q >= lo[k] - 1e-6) & (q <= hi[k] + 1e-6)).all())
    # the reported error is what forward kinematics of the returned joints gives
    tips = hand.fingertips_base(q3.unsqueeze(1).expand(-1, 5, -1).contiguous())[:, k]
    assert torch.allclose((tips - x).norm(dim=-1), e3, atol=1e-6)


def test_refinement_never_increases_error(ik):
    _, x = heldout_targets(ik, "thumb", n=2000, seed=77)
    errors = [ik.solve("thumb", x, refine=r)[1] for r in range(4)]
    for a, b in itertools.pairwise(errors):
        assert bool((b <= a + 1e-9).all())


def test_all_fingers_at_once_equals_one_by_one(ik, hand):
    xs = torch.stack([heldout_targets(ik, f, n=300, seed=5)[1] for f in hand.finger_names], dim=1)
    q_all, e_all = ik.solve_fingers(xs, refine=2)
    for k, f in enumerate(hand.finger_names):
        q, e = ik.solve(f, xs[:, k], refine=2)
        assert torch.allclose(q, q_all[:, k], atol=1e-6) and torch.allclose(e, e_all[:, k], atol=1e-7)


def test_unreachable_targets_come_back_with_their_error(ik):
    far = torch.tensor([[1.0, 1.0, 1.0], [0.0, 0.0, -0.5]])
    q, err = ik.solve("index", far, refine=3)
    assert q.shape == (2, 4) and bool((err > 0.4).all())


@pytest.mark.parametrize(("targets", "error", "message"), [
    (torch.zeros(5, 2), ValueError, r"shape \(B, 3\)"),
    (torch.zeros(3), ValueError, r"shape \(B, 3\)"),
    (torch.tensor([[0.0, float("nan"), 0.0]]), ValueError, "NaN or inf"),
    (torch.tensor([[0.0, float("inf"), 0.0]]), ValueError, "NaN or inf"),
    (torch.zeros(4, 3, dtype=torch.int64), TypeError, "floating-point"),
])
def test_bad_targets(ik, targets, error, message):
    with pytest.raises(error, match=message):
        ik.solve("index", targets)


def test_unknown_finger(ik):
    with pytest.raises(ValueError, match="no experts for finger 'little'"):
        ik.solve("little", torch.zeros(2, 3))


def test_checkpoint_round_trip(ik, hand, tmp_path):
    path = save_finger_ik(ik, tmp_path / "fcnn.pt", {"note": "test"})
    again = load_finger_ik(hand, path)
    _, x = heldout_targets(ik, "ring", n=500, seed=3)
    assert torch.equal(ik.solve("ring", x, refine=1)[0], again.solve("ring", x, refine=1)[0])


def test_corrupted_checkpoint_names_the_file(hand, tmp_path):
    path = tmp_path / "broken.pt"
    path.write_bytes(default_checkpoint("hand").read_bytes()[:5000])
    with pytest.raises(gt.CheckpointError, match=r"broken.pt: not a readable checkpoint"):
        load_finger_ik(hand, path)
    path.write_bytes(b"not a checkpoint at all")
    with pytest.raises(gt.CheckpointError, match=r"broken.pt"):
        load_finger_ik(hand, path)


def test_missing_checkpoint(hand, tmp_path):
    with pytest.raises(gt.CheckpointError, match=r"nope.pt: FCNN checkpoint not found"):
        load_finger_ik(hand, tmp_path / "nope.pt")


def test_checkpoint_for_another_robot_or_chain_is_refused(ik, robots, tmp_path):
    arm_hand = robots["arm_hand"]  # same fingers, other robot name
    with pytest.raises(gt.CheckpointError, match=r"fcnn.pt: trained for robot 'hand', not 'arm_hand'"):
        load_finger_ik(arm_hand, default_checkpoint("hand"))
    # a hand whose index finger has other joint limits: same names, different chain
    urdf = load_robot_cfg("hand").urdf.read_text()
    assert 'upper="1.919862177"' in urdf  # 110 deg, first used by index_pip
    urdf = urdf.replace('upper="1.919862177"', 'upper="1.8"', 1)
    (tmp_path / "hand.urdf").write_text(urdf)
    cfg = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    cfg["urdf"] = str(tmp_path / "hand.urdf")
    (tmp_path / "hand.yaml").write_text(yaml.safe_dump(cfg))
    changed = gt.load_robot(tmp_path / "hand.yaml")
    with pytest.raises(gt.CheckpointError, match=r"finger '\w+' was trained for a different chain"):
        load_finger_ik(changed, default_checkpoint("hand"))


@pytest.mark.slow
def test_candidates_and_fallback_never_worsen_and_rescue_poor_answers(hand, index_chain):
    """With an untrained expert the winner's answer is poor; refining more candidates and the
    random-restart fallback can only lower the error, and the fallback solves most targets."""
    from graspnet_torch.fcnn.train import FCNNTrainCfg, FingerTrainer

    trainer = FingerTrainer(index_chain, FCNNTrainCfg(val_targets=500), seed=0)  # never trained
    untrained = FingerIK(hand, {"index": trainer.experts})
    x = trainer.val_x
    _, e1 = untrained.solve("index", x, refine=1)
    _, e2 = untrained.solve("index", x, refine=1, candidates=2)
    _, e3 = untrained.solve("index", x, refine=1, fallback_restarts=10)
    assert bool((e2 <= e1 + 1e-9).all()) and bool((e3 <= e1 + 1e-9).all())
    assert float((e1 < 1e-3).float().mean()) < 0.5
    assert float((e3 < 1e-3).float().mean()) > 0.95
    again = untrained.solve("index", x, refine=1, fallback_restarts=10)[1]
    assert torch.equal(again, e3)  # deterministic


@pytest.mark.parametrize(("key", "value", "message"), [
    ("W2", float("nan"), r"finger 'index': non-finite values \(NaN or infinity\) in W2"),
    ("b3", float("inf"), r"non-finite values \(NaN or infinity\) in b3"),
    ("x_scale", 0.0, r"input scales must be positive"),
])
def test_checkpoint_with_non_finite_weights_or_zero_scale_is_refused(ik, hand, tmp_path, key, value, message):
    path = save_finger_ik(ik, tmp_path / "fcnn.pt")
    payload = torch.load(path, weights_only=True)
    payload["fingers"]["index"]["state"][key].view(-1)[0] = value
    torch.save(payload, path)
    with pytest.raises(gt.CheckpointError, match=message):
        load_finger_ik(hand, path)
