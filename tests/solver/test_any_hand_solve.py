"""The odd hand (tests/odd_hands.py) end to end: per-finger expert sets sized from each chain,
one batched FCNN call over fingers of different sizes, checkpoint round trip, a solve whose
result is recomputed from the URDF with mimic couplings exact."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.fcnn import load_finger_ik
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.jobs.train_fcnn import train_fcnn
from graspnet_torch.tasks import random_sequence
from tests.odd_hands import MIMIC, pk_fingertips_palm, write_odd_arm, write_oddhand

pytestmark = pytest.mark.slow  # every test shares a module fixture that trains the odd hand's FCNN

TINY = FCNNTrainCfg.from_mapping({"epochs": 12, "targets_per_epoch": 96, "train_steps": 15, "val_targets": 500,
                                  "val_every": 12})


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    folder = tmp_path_factory.mktemp("oddhand")
    robot = gt.load_robot(str(write_oddhand(folder)))
    ik, rows = train_fcnn(robot, TINY, folder / "run", export=True, progress=False, eval_targets=500)
    return robot, ik, rows


def test_expert_sets_are_sized_from_each_chain_and_exported_beside_the_config(trained):
    robot, ik, rows = trained
    assert {f: ik.experts[f].n_joints for f in robot.finger_names} == {"thumb": 4, "index": 3, "middle": 2, "ring": 2}
    assert [r["finger"] for r in rows] == list(robot.finger_names)
    assert robot.cfg.checkpoint.is_file()
    loaded = load_finger_ik(robot)  # found beside the config
    x = robot.fingertips_base(torch.zeros(1, 4, 4)).float().expand(5, 4, 3)
    torch.testing.assert_close(loaded.solve_fingers(x)[0], ik.solve_fingers(x)[0])


def test_one_batched_call_over_fingers_of_different_sizes(trained, gen):
    robot, ik, _ = trained
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    q_true = (lo + (hi - lo) * torch.rand(200, *lo.shape, generator=gen, dtype=torch.float64)).float()
    targets = robot.fingertips_base(q_true)
    q, err = ik.solve_fingers(targets, refine=5)
    assert q.shape == (200, 4, 4)
    assert torch.all(q[:, torch.as_tensor(~robot.finger_mask)] == 0)  # padding stays 0
    assert torch.all((q >= lo.float() - 1e-6) & (q <= hi.float() + 1e-6))
    # each finger alone gives the same answer, in its own width
    for k, f in enumerate(robot.finger_names):
        q_k, err_k = ik.solve(f, targets[:, k], refine=5)
        assert q_k.shape == (200, robot.fingers[f].n_joints)
        torch.testing.assert_close(q_k, q[:, k, : q_k.shape[1]], rtol=0, atol=1e-4)  # float32 refinement
        torch.testing.assert_close(err_k, err[:, k], rtol=0, atol=2e-6)
    torch.testing.assert_close(err, (robot.fingertips_base(q) - targets).norm(dim=-1), rtol=0, atol=1e-6)
    assert float((err < 1e-3).float().mean()) > 0.9  # 12 tiny epochs and 5 refinement steps


@pytest.mark.parametrize("seed", [3, 8])
def test_solve_recomputed_from_the_urdf_with_exact_mimic_couplings(trained, seed):
    robot, ik, _ = trained
    problem = gt.random_reachable_problem(robot, seed, n_fingers=(2, 3))
    result = gt.solve(problem, trials=8, seed=0, robot=robot, finger_ik=ik, max_iterations=300,
                      solver={"polish": {"mode": "whole"}})
    assert result.total_error_mm < 1.0
    data = json.loads(result.to_json())
    joints = data["joints"]
    assert [len(joints[f]) for f in robot.finger_names] == [4, 4, 2, 2]  # every joint, mimic included
    _leader, m, b = MIMIC["index_dip"]
    pip, dip = math.radians(joints["index"][2]), math.radians(joints["index"][3])
    assert dip == pytest.approx(m * pip + b, abs=1e-9)
    # from the URDF alone: pytorch-kinematics with the reported joints and palm pose
    q = robot.finger_joints_from_file(joints).unsqueeze(0)
    pose = torch.tensor(data["palm_pose"][:3] + [math.radians(a) for a in data["palm_pose"][3:]], dtype=torch.float64)
    R, t = gt.robot.transforms.pose_to_rt(pose)
    tips = (pk_fingertips_palm(robot, q)[0] @ R.T + t).numpy()
    for c in problem.contacts:
        k = robot.finger_index(c.finger)
        world = problem.contacts_world()[problem.fingers.index(c.finger)]
        err_mm = float(np.linalg.norm(tips[k] - world)) * 1000
        assert err_mm == pytest.approx(data["fingertip_error_mm"][c.finger], abs=1e-4)


def test_an_arm_carries_another_hand(trained, tmp_path):
    """An arm_hand-like config naming an arm chain and this hand: the arm's loop (ACNN) places the
    palm, the same FCNN (identical finger chains) places the fingers."""
    robot, _ik, _ = trained
    arm = gt.load_robot(str(write_odd_arm(tmp_path, checkpoint=str(robot.cfg.checkpoint))))
    assert arm.body_joint_names == ("shoulder_yaw", "shoulder_pitch", "elbow", "wrist_roll")
    assert arm.dof == 4 + 11
    arm_ik = load_finger_ik(arm)  # the hand's checkpoint: fingerprints match
    problem = gt.random_reachable_problem(arm, 2, n_fingers=2)
    result = gt.solve(problem, trials=8, seed=0, robot=arm, finger_ik=arm_ik, max_iterations=400,
                      solver={"polish": {"mode": "whole"}})
    data = json.loads(result.to_json())
    assert list(data["arm_joints"]) == list(arm.body_joint_names)
    assert result.total_error_mm < 1.0
    body = torch.tensor([math.radians(data["arm_joints"][n]) for n in arm.body_joint_names], dtype=torch.float64)
    tips = arm.fingertips_world_from_body(body, arm.finger_joints_from_file(data["joints"]))
    for c, world in zip(problem.contacts, problem.contacts_world(), strict=True):
        err_mm = float(torch.linalg.vector_norm(tips[arm.finger_index(c.finger)] - torch.as_tensor(world))) * 1000
        assert err_mm == pytest.approx(data["fingertip_error_mm"][c.finger], abs=1e-4)


def test_tracking_the_odd_hand_bounds_each_free_joints_step(trained):
    """Fingers of different sizes, a mimic joint: a tracked sequence's warm starts move no free
    finger joint more than solver.polish.warm_step_deg (the padding slots never move) and land."""
    robot, ik, _ = trained
    frames = random_sequence(robot, 5, 8, (3, 4))
    results = gt.Solver(robot, trials=8, finger_ik=ik).track(frames)
    step = math.radians(gt.SolverCfg().polish.warm_step_deg)
    idx = [robot.finger_index(f) for f in frames[0].fingers]
    for a, b in itertools.pairwise(results):
        if len(b.trials) == 1:  # a warm start's own trial
            qa, qb = (robot.finger_joints_from_file(r.best.joints)[idx] for r in (a, b))
            assert float((qa - qb).abs().max()) <= step + 1e-6
    assert sum(r.success for r in results) >= 7
