"""The reported grasp passes what was asked (graspnet_torch.jobs.verify): ``verify=physics`` and
``reach=true`` go through the successful trials best first and report the first that holds its
object in MuJoCo (and, with reach, has a motion); what cannot be checked is refused before any work."""

from __future__ import annotations

import importlib.util
import json
import sys

import numpy as np
import pytest
import torch

from graspnet_torch.jobs.cli import check_overrides, compose_for_check, hydra_overrides
from graspnet_torch.jobs.configs import SolveGraspJobCfg
from graspnet_torch.jobs.solve_grasp import job_settings
from graspnet_torch.jobs.verify import NO_GRASP, REQUIRED_HOLDS, ranking, verify_result
from graspnet_torch.motion import ReachCfg
from graspnet_torch.physics import PhysicsCfg
from graspnet_torch.solver.result import GraspResult, Trajectory, TrialResult
from tests.in_process import run_script
from tests.physics.test_physics import pinch  # noqa: F401  (a fixture: the solved pad pinch and its squeeze)
from tests.refusals import refused, write_problem

needs_mujoco = pytest.mark.skipif(importlib.util.find_spec("mujoco") is None,
                                  reason="the physics check needs MuJoCo (pip install mujoco; the dev extra has it)")

PINCH = """robot: hand
object: {shape: box, size: [0.04, 0.04, 0.04], pose: [0, 0, 0, 0, 0, 0]}
contacts:
  - {finger: thumb, position: [0.028075, 0, 0]}
  - {finger: index, position: [-0.027225, 0, 0]}
"""  # thumb and index fingertip centres a fingertip radius out from opposite faces of a 4 cm box (point model)
PAD_PINCH = """robot: hand
object: {shape: box, size: [0.04, 0.04, 0.04], pose: [0, 0, 0, 0, 0, 0]}
contacts:
  - {finger: thumb, position: [0.02, 0, 0]}
  - {finger: index, position: [-0.02, 0, 0]}
"""  # the same pinch in the default (surface) model: the contacts on the faces, where the pads go
NO_OBJECT = """robot: hand
contacts:
  - {finger: thumb, position: [0.03, 0, 0]}
  - {finger: index, position: [-0.03, 0, 0]}
"""


def _trial(error_mm: float, success: bool = True, collisions: int = 0) -> TrialResult:
    return TrialResult(success, 10, 0.9, 0.01, collisions, error_mm, total_error_mm=error_mm)


def _motion(found: bool) -> Trajectory:
    if not found:
        return Trajectory.missing(["palm_x"], np.array([False]), "no collision-free path", 0.1)
    return Trajectory(["palm_x"], np.array([0.0, 1.0]), np.zeros((2, 1)), np.array([False]))


class Planner:
    """A stub of gt.plan_reach: a motion found for the trials in ``found``; records what it planned."""

    def __init__(self, found: set[int]):
        self.found, self.planned = found, []

    def __call__(self, problem, result, cfg, robot) -> Trajectory:
        self.planned.append(result.chosen)
        return _motion(result.chosen in self.found)


# ------------------------------------------------------------------ the order and the reach check
def test_ranking_is_the_order_result_best_chooses():
    result = GraspResult("hand", [_trial(0.5), _trial(0.1, success=False), _trial(0.3), _trial(0.2, collisions=1),
                                  _trial(0.4)])
    assert ranking(result) == [2, 4, 0, 3]
    assert result.trials[ranking(result)[0]] is result.best
    result.chosen = 4  # a solver's own choice (tracking) comes first
    assert ranking(result) == [4, 2, 0, 3]


def test_reach_reports_the_best_trial_whose_motion_is_found():
    result = GraspResult("hand", [_trial(0.3), _trial(0.1), _trial(0.2)])
    planner = Planner(found={0})
    verification = verify_result(None, None, result, None, ReachCfg(enabled=True), planner=planner, log=None)
    assert planner.planned == [1, 2, 0]  # best first; stops at the first found
    assert result.chosen == 0 and result.best is result.trials[0] and result.trajectory.found
    assert verification.passed and verification.checked == 3
    data = result.to_dict()
    assert data["verified"] == {"what": ["reach"], "checked": 3, "passed": True, "trials": [
        {"trial": 1, "passed": False, "why": "reach: no collision-free path"},
        {"trial": 2, "passed": False, "why": "reach: no collision-free path"}, {"trial": 0, "passed": True}]}
    assert data["trials"][0]["verified"] == data["verified"] and "verified" not in data["trials"][1]
    assert data["total_error_mm"] == 0.3 and "physics" not in data
    assert GraspResult.from_dict(data).chosen == 0  # read back: the reported trial is the verified one


def test_when_no_trial_passes_the_best_is_reported_with_its_checks():
    result = GraspResult("hand", [_trial(0.3), _trial(0.1), _trial(0.2), _trial(0.4)])
    planner = Planner(found=set())
    lines = []
    verification = verify_result(None, None, result, None, ReachCfg(enabled=True), limit=2, planner=planner,
                                 log=lines.append)
    assert planner.planned == [1, 2]  # at most `limit` trials; the best's motion is not planned twice
    assert result.chosen == 1 and not result.trajectory.found and not verification.passed
    assert result.to_dict()["verified"]["checked"] == 2 and len(lines) == 2
    assert "none of the 2 successful trial(s) checked passes reach" in verification.summary()


def test_no_successful_trial_checks_nothing(hand):
    result = GraspResult("hand", [_trial(5.0, success=False), _trial(3.0, success=False)])
    planner = Planner(found={0, 1})
    verification = verify_result(hand, None, result, None, ReachCfg(enabled=True), planner=planner, log=None)
    assert planner.planned == [] and verification.checked == 0 and result.chosen == 1
    assert result.trajectory.reason == NO_GRASP and result.to_dict()["verified"]["passed"] is False


# ------------------------------------------------------------------ the physics check
@needs_mujoco
@pytest.mark.slow
def test_best_trial_that_drops_the_object_gives_way_to_one_that_holds(hand, pinch):  # noqa: F811
    """Two successful trials: the better ranked one an open hand at the pinch's palm (holds 0-1/6),
    the other the squeezed pinch (holds 6/6): the second is reported."""
    problem, solved, grasp, _ = pinch
    held = solved.best
    fields = {k: v for k, v in held.fields.items() if k not in ("squeeze", "physics", "verified")}
    open_hand = TrialResult(True, 10, 0.9, 0.01, 0, 0.0, **{**fields, "joints": hand.finger_joints_to_file(
        torch.zeros_like(grasp.fingers))})
    squeezed = TrialResult(True, 10, 0.9, 0.01, 0, 0.5, **fields, squeeze=held.fields["squeeze"])
    result = GraspResult("hand", [open_hand, squeezed], problem="pinch")
    planner = Planner(found={0, 1})
    verification = verify_result(hand, problem, result, PhysicsCfg(), ReachCfg(enabled=True), planner=planner,
                                 log=None)
    assert planner.planned == [1]  # the open hand failed physics: no motion planned for it
    assert verification.passed and result.chosen == 1 and verification.checked == 2
    data = result.to_dict()
    assert data["trials"][0]["physics"]["holds"] <= 1 and data["physics"]["holds"] == REQUIRED_HOLDS == 6
    assert data["verified"]["trials"][0] == {"trial": 0, "passed": False,
                                             "why": f"physics holds {data['trials'][0]['physics']['holds']}/6"}
    assert data["trajectory"]["found"] and data["joints"] == squeezed.to_dict()["joints"]


@needs_mujoco
@pytest.mark.slow
def test_verify_physics_from_the_command_line(tmp_path):
    """The pinch of a 4 cm box, pads on opposite faces, every trial run to its end: the reported
    trial is the first successful one, best first, that holds 6/6; each checked trial carries its
    physics report."""
    out = tmp_path / "r.json"
    res = run_script("solve_grasp.py", f"problem={write_problem(tmp_path, PAD_PINCH)}", "verify=physics",
                     "solver.stop=null", "trials=16", "seed=0", f"out={out}", f"hydra.run.dir={tmp_path / 'run'}",
                     "tensorboard=false", "pictures=false")
    assert res.returncode == 0, res.stderr
    data = json.loads(out.read_text())
    verified, trials = data["verified"], data["trials"]
    checked = [c["trial"] for c in verified["trials"]]
    ok = [k for k, t in enumerate(trials) if t["success"]]
    order = sorted(ok, key=lambda k: (trials[k]["collisions"] > 0, trials[k]["total_error_mm"]))
    assert checked == order[:len(checked)] and verified["checked"] == len(checked) >= 1
    assert all("physics" in trials[k] for k in checked)
    assert all("physics" not in t for k, t in enumerate(trials) if k not in checked)
    assert [c["passed"] for c in verified["trials"]] == [False] * (len(checked) - 1) + [verified["passed"]]
    chosen = checked[-1] if verified["passed"] else order[0]
    assert {k: v for k, v in data.items() if k in trials[chosen]} == trials[chosen]
    assert verified["passed"], res.stderr  # a pad pinch of a box holds
    assert data["physics"]["holds"] == 6 and "verified: trial" in res.stdout
    assert f"{len(checked)} trial(s) checked" in res.stdout


@needs_mujoco
@pytest.mark.slow
def test_verify_physics_with_reach_and_a_physics_setting(tmp_path):
    out = tmp_path / "r.json"
    res = run_script("solve_grasp.py", "task=videotape5", "verify=physics", "reach=true", "physics.friction=0.8",
                     f"out={out}", f"hydra.run.dir={tmp_path / 'run'}", "tensorboard=false", "pictures=false")
    assert res.returncode == 0, res.stderr
    data = json.loads(out.read_text())
    assert data["verified"]["what"] == ["physics", "reach"]
    assert data["physics"]["protocol"]["friction"] == [0.8, 0.02]
    if data["verified"]["passed"]:
        assert data["physics"]["holds"] == 6 and data["trajectory"]["found"]


# ------------------------------------------------------------------ settings and refusals
def test_physics_settings_compose_and_the_file_lists_them_all():
    argv = hydra_overrides(["task=videotape5", "verify=physics", "physics.friction=0.8", "physics.push_s=1"],
                           SolveGraspJobCfg)
    check_overrides(argv, SolveGraspJobCfg)
    [(cfg, _)] = compose_for_check("solve_grasp", argv)
    job = job_settings(cfg)[0]
    assert job.verify == "physics" and job.physics == PhysicsCfg(friction=0.8, push_s=1.0)
    [(cfg, _)] = compose_for_check("solve_grasp", ["task=videotape5"])
    assert set(cfg["physics"]) == set(PhysicsCfg.__dataclass_fields__)  # so that physics.KEY=V reaches each
    assert job_settings(cfg)[0].verify == "none" and job_settings(cfg)[0].physics == PhysicsCfg()


def test_verify_physics_without_an_object_is_refused(tmp_path):
    path = write_problem(tmp_path, NO_OBJECT)
    refused(tmp_path, "solve_grasp.py", f"problem={path}", f"out={tmp_path / 'r.json'}", "verify=physics",
            message=f"verify=physics: {path} has no object")
    assert not (tmp_path / "r.json").exists()


def test_verify_physics_without_mujoco_is_refused(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    refused(tmp_path, "solve_grasp.py", "task=videotape5", f"out={tmp_path / 'r.json'}", "verify=physics",
            message="verify=physics needs MuJoCo: pip install mujoco")


@pytest.mark.parametrize(("args", "message"), [
    (["verify=maybe"], "verify='maybe'"),
    (["verify=physics", "physics.friction=-1"], "physics.friction=-1"),
    (["verify=physics", "physics.nope=1"], "unknown setting 'physics.nope'"),
    (["verify=physics", "physics.until_failure=maybe"], "physics.until_failure='maybe': expected true or false"),
    (["verify_trials=0"], "verify_trials=0"),
])
def test_bad_verify_settings_are_refused(tmp_path, args, message):
    refused(tmp_path, "solve_grasp.py", "task=videotape5", f"out={tmp_path / 'r.json'}", *args, message=message)

