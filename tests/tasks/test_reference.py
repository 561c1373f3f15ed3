from __future__ import annotations

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.jobs.reference_posture import reference_posture
from graspnet_torch.solver.reference_fit import find_reference_posture


@pytest.mark.slow
def test_fit_finds_an_exact_posture_for_a_reachable_problem(hand):
    b = hand.palm_bounds
    pose = torch.as_tensor(b.lower + (b.upper - b.lower) * 0.5, dtype=torch.float64)
    q = hand.home_posture().fingers.clone()
    q[1] += torch.tensor([0.05, 0.3, 0.4, 0.2], dtype=torch.float64)
    tips = hand.fingertips_world(pose, q)
    contacts = [{"finger": f, "position": tips[hand.finger_index(f)].tolist()} for f in ("thumb", "index")]
    problem = gt.GraspProblem.from_mapping({"robot": "hand", "palm_bounds": "robot", "contacts": contacts}, source="t")
    fit = find_reference_posture(hand, problem, restarts=2, seed=1)
    assert fit.total < 2e-4
    assert bool((fit.palm_pose >= b.lower - 1e-12).all() and (fit.palm_pose <= b.upper + 1e-12).all())
    anywhere = gt.GraspProblem.from_mapping({"robot": "hand", "contacts": contacts}, source="t")  # the search
    fit = find_reference_posture(hand, anywhere, restarts=2, seed=1)  # space built from the contacts
    q = hand.home_posture().fingers.clone()
    for f, v in fit.joints.items():
        q[hand.finger_index(f)] = torch.as_tensor(v)
    got = hand.fingertips_world(torch.as_tensor(fit.palm_pose), q)  # the world palm pose it reports
    for c in contacts:
        assert float((got[hand.finger_index(c["finger"])] - torch.tensor(c["position"])).norm()) < 2e-4


@pytest.mark.slow
def test_job_prints_a_reference_block(capsys):
    fit = reference_posture({"task": "glass3", "restarts": 4})
    out = capsys.readouterr().out
    assert "reference:" in out and "palm_pose:" in out and "thumb:" in out
    assert fit.total < 5e-4
