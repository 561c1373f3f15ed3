"""Results read back: GraspResult.from_dict is the inverse of to_dict (and of the JSON file)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.solver.result import GraspResult, Trajectory, TrialResult


@pytest.mark.parametrize("task", ["glass3", "cube"])
def test_round_trip_of_a_solved_result(task, tmp_path):
    r = gt.solve(task, trials=3, seed=0)
    back = GraspResult.from_dict(r.to_dict())
    assert back.to_dict() == r.to_dict()
    assert back.best.to_dict() == r.best.to_dict() and back.best.error_mm == r.best.error_mm
    path = r.save(tmp_path / "result.json")
    assert GraspResult.from_dict(json.loads(path.read_text())).to_dict() == json.loads(r.to_json())


def test_round_trip_with_failure_and_trajectory():
    trials = [TrialResult(False, 5, 0.5, 0.1, 2, palm_pose=[0.0] * 6, total_error_mm=3.0),
              TrialResult(False, 5, 0.6, 0.1, 0, palm_pose=[1.0] * 6, total_error_mm=4.0)]
    revolute = np.array([False, True])
    motion = Trajectory(["a", "b"], np.array([0.0, 1.0]), np.array([[0.0, 0.1], [0.2, 0.3]]), revolute)
    r = GraspResult("hand", trials, problem="p.yaml", seed=3, settings={"x": 1}, failure="no grasp", chosen=1,
                    trajectory=motion)
    back = GraspResult.from_dict(r.to_dict(), revolute)
    assert back.to_dict() == r.to_dict()
    assert back.chosen == 1 and back.failure == "no grasp"
    assert "trajectory" not in GraspResult.from_dict(r.to_dict()).to_dict()  # no revolute: left out


def test_a_summary_without_trials_is_its_one_trial():
    r = GraspResult.from_dict({"robot": "manus", "success": True, "distance_mm": 0.25})
    assert r.success and r.best.error_mm == 0.25 and len(r.trials) == 1
    with pytest.raises(TypeError):
        GraspResult.from_dict({"robot": "hand", "trials": []})
