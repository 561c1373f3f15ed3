"""The physics check of a grasp in MuJoCo (gt.simulate_grasp): it fails grasps that do not hold, it
passes a pad pinch that does, its report's JSON shape, its protocol's settings reach the model, and
its model's kinematics are the package's."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.physics import DIRECTIONS, PhysicsCfg, PhysicsReport, simulate_grasp
from graspnet_torch.robot.ik import refine
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import GraspResult
from tests.mesh_robots import mesh_hand_urdf, write_box_mesh, write_robot
from tests.mujoco_models import posed_model
from tests.odd_hands import MIMIC, write_oddhand

needs_mujoco = pytest.mark.skipif(importlib.util.find_spec("mujoco") is None,
                                  reason="the physics check needs MuJoCo (pip install mujoco; the dev extra has it)")

HALF = 0.02  # the pinched box: a 4 cm cube at the world origin
R_THUMB, R_INDEX = 0.008075, 0.007225  # the fingertip spheres' radii (urdf/hand/hand.urdf, thumb_distal, index_distal)
SQUEEZE = 0.005  # the fingertips commanded this much further into the box


def pinch_problem() -> gt.GraspProblem:
    """Thumb and index on opposite faces of the box, each contact (its fingertip sphere's centre)
    its radius out from the face: the pads touch the box."""
    return gt.GraspProblem.from_mapping({
        "robot": "hand", "object": {"shape": "box", "size": [2 * HALF] * 3, "pose": [0, 0, 0, 0, 0, 0]},
        "contacts": [{"finger": "thumb", "position": [HALF + R_THUMB, 0, 0]},
                     {"finger": "index", "position": [-HALF - R_INDEX, 0, 0]}]})


@pytest.fixture(scope="module")
def pinch(hand):
    """The solved pinch, with the squeeze posture (the palm held, thumb and index tips SQUEEZE
    further in, by the package's IK) in its reported trial: (problem, result, grasp, squeeze)."""
    problem = pinch_problem()
    result = gt.solve(problem, trials=8, seed=0, solver={"contact_model": "point"})  # contacts at the tips' centres
    assert result.success and result.best.collisions == 0
    grasp = trial_posture(hand, result.best)
    tips = hand.fingertips_world(grasp.palm_pose, grasp.fingers).clone()
    tips[0] = torch.tensor([HALF + R_THUMB - SQUEEZE, 0, 0], dtype=torch.float64)
    tips[1] = torch.tensor([-HALF - R_INDEX + SQUEEZE, 0, 0], dtype=torch.float64)
    lower, upper = (torch.as_tensor(a) for a in hand.finger_limits)
    q, err = refine(hand.fingertips_base_jacobian, grasp.fingers.clone(), hand.world_to_bases(tips, grasp.palm_pose),
                    lower, upper, 100)
    assert float(err.max()) < 1e-6
    result.best.fields["squeeze"] = {"palm_pose": result.best.palm_pose, "joints": hand.finger_joints_to_file(q)}
    return problem, result, grasp, gt.Posture(grasp.palm_pose, q, grasp.body)


def summary(report: PhysicsReport) -> str:
    shifts = ", ".join(f"{d} {report.shifts_mm[d]:.1f} mm {report.turns_deg[d]:.1f} deg" for d in DIRECTIONS)
    return f"holds {report.holds}/6; settle {report.settle_shift_mm:.2f} mm; {shifts}"


# ---------------------------------------------------------------------------- it can pass
@needs_mujoco
def test_squeezed_pad_pinch_holds(pinch):
    problem, result, _, _ = pinch
    report = simulate_grasp(problem, result)
    assert report.holds >= 5, summary(report)
    assert not report.moved_while_settling, summary(report)


@needs_mujoco
def test_squeeze_read_back_from_the_result_file(pinch):
    """The squeeze travels in the result JSON (the trial's ``squeeze``): the same check."""
    problem, result, _, _ = pinch
    again = GraspResult.from_dict(result.to_dict())
    assert again.best.fields["squeeze"] == result.best.fields["squeeze"]
    assert simulate_grasp(problem, again).to_dict() == simulate_grasp(problem, result).to_dict()


# ---------------------------------------------------------------------------- it can fail
@needs_mujoco
@pytest.mark.parametrize("fingers", ["zero", "home"])
def test_open_hand_at_the_grasp_palm_fails(hand, pinch, fingers):
    problem, result, grasp, _ = pinch
    q = torch.zeros_like(grasp.fingers) if fingers == "zero" else hand.home_posture().fingers
    report = simulate_grasp(problem, result, posture=gt.Posture(grasp.palm_pose, q, grasp.body))
    assert report.holds <= 1, summary(report)


@needs_mujoco
@pytest.mark.parametrize("finger", [0, 1])
def test_one_finger_grasp_fails(pinch, finger):
    """Only one finger (squeezed into the box), every other open."""
    problem, result, grasp, squeeze = pinch
    q = torch.zeros_like(grasp.fingers)
    q[finger] = squeeze.fingers[finger]
    report = simulate_grasp(problem, result, posture=gt.Posture(grasp.palm_pose, q, grasp.body))
    assert report.holds <= 1, summary(report)


@needs_mujoco
def test_without_friction_the_pinch_fails(pinch):
    """The protocol's settings reach the model: friction 0 lets the object slide out."""
    problem, result, _, _ = pinch
    report = simulate_grasp(problem, result, PhysicsCfg(friction=0.0, torsional_friction=0.0))
    assert report.holds <= 1, summary(report)
    assert report.protocol["friction"] == [0.0, 0.0]


@needs_mujoco
@pytest.mark.parametrize("grasp", ["pinch", "one finger"])
def test_until_failure_is_the_full_check_cut_after_its_first_failed_push(pinch, grasp):
    """``until_failure`` (``gt.check_until_failure``): the full check's pushes up to and including
    its first failure, each with the same shift (every push starts from the same settled state),
    and the same verdict on every push held."""
    problem, result, grasp_posture, squeeze = pinch
    posture = None
    if grasp == "one finger":
        q = torch.zeros_like(grasp_posture.fingers)
        q[0] = squeeze.fingers[0]
        posture = gt.Posture(grasp_posture.palm_pose, q, grasp_posture.body)
    full = simulate_grasp(problem, result, posture=posture)
    short = simulate_grasp(problem, result, PhysicsCfg(until_failure=True), posture=posture)
    names = list(full.directions)
    failed = [n for n in names if not full.directions[n]]
    run = names if not failed else names[: names.index(failed[0]) + 1]
    assert list(short.directions) == run and all(short.directions[n] == full.directions[n] for n in run)
    assert all(short.shifts_mm[n] == pytest.approx(full.shifts_mm[n], abs=1e-9) for n in run)
    assert short.held_all == full.held_all and short.of == full.of == 6
    assert short.to_dict()["physics"]["pushes_run"] == len(run)
    if grasp == "one finger":
        assert len(run) < 6, summary(full)
    if posture is None:
        assert gt.check_until_failure(problem, result).to_dict() == short.to_dict()


# ---------------------------------------------------------------------------- the report
@needs_mujoco
def test_a_check_is_the_same_whichever_check_of_the_robot_came_before(pinch):
    """The model is compiled once per robot and object and its posed bodies (the palm) set for each
    check: the pinch checked on a robot fresh from its config, and again after a check with the
    palm moved away, reports the same to the last bit; the moved palm's check is a fresh robot's."""
    problem, result, grasp, _ = pinch
    moved = gt.Posture(grasp.palm_pose + torch.tensor([0.0, 0.0, 0.03, 0.0, 0.0, 0.0], dtype=torch.float64),
                       grasp.fingers, grasp.body)

    def check(robot, posture=None):
        r = simulate_grasp(problem, result, posture=posture, robot=robot)
        return r.directions, r.shifts_mm, r.turns_deg, r.settle_shift_mm

    robot = gt.load_robot("hand")
    first = check(robot)
    away = check(robot, moved)
    assert check(robot) == first and sum(first[0].values()) >= 5
    assert away == check(gt.load_robot("hand"), moved) and sum(away[0].values()) < 6


@needs_mujoco
def test_report_json_shape(pinch):
    problem, result, _, _ = pinch
    out = simulate_grasp(problem, result).to_dict()
    assert list(out) == ["physics"]
    physics = out["physics"]
    assert set(physics) == {"holds", "of", "pushes_run", "directions", "settle_shift_mm", "settle_turn_deg",
                            "moved_while_settling", "protocol"}
    assert physics["of"] == physics["pushes_run"] == 6
    assert list(physics["directions"]) == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert physics["holds"] == sum(physics["directions"].values())
    assert all(isinstance(v, bool) for v in physics["directions"].values())
    assert isinstance(physics["moved_while_settling"], bool)
    assert all(isinstance(physics[k], float) for k in ("settle_shift_mm", "settle_turn_deg"))
    assert physics["protocol"] == {"friction": [0.6, 0.02], "object_mass_kg": 0.1, "duration_s": 2.0,
                                   "max_shift_mm": 50.0, "max_turn_deg": 15.0, "timestep_s": 0.004}


def test_settings_are_checked():
    from graspnet_torch.settings import build

    assert build(PhysicsCfg, {"friction": 0.3}).friction == 0.3
    with pytest.raises(ConfigError):
        build(PhysicsCfg, {"object_mass_kg": 0.0})
    with pytest.raises(ConfigError):
        build(PhysicsCfg, {"bogus": 1})


def test_missing_mujoco_is_one_clear_line(monkeypatch, pinch):
    problem, result, _, _ = pinch
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    with pytest.raises(ConfigError, match="pip install mujoco"):
        simulate_grasp(problem, result)


@needs_mujoco
def test_a_problem_without_an_object_is_refused(pinch):
    problem, result, _, _ = pinch
    bare = gt.GraspProblem.from_mapping({"robot": "hand", "contacts": [
        {"finger": c.finger, "position": c.position.tolist()} for c in problem.contacts]})
    with pytest.raises(ProblemError, match="object"):
        simulate_grasp(bare, result)


# ---------------------------------------------------------------------------- the model
def _frames_agree(robot, posture, obj) -> None:
    """The compiled model's bodies sit where the package's forward kinematics puts the links."""
    model, data, built = posed_model(robot, obj, posture)
    for link, T in robot.link_frames(posture).items():
        body = model.body("urdf_world" if link == "world" else link).id
        np.testing.assert_allclose(data.xpos[body], T[:3, 3], atol=1e-9, err_msg=link)
        np.testing.assert_allclose(data.xmat[body].reshape(3, 3), T[:3, :3], atol=1e-9, err_msg=link)
    return model, built


@needs_mujoco
@pytest.mark.parametrize("name", ["hand", "arm_hand"])
def test_model_frames_are_the_package_kinematics(robots, name, pinch):
    robot = robots[name]
    gen = torch.Generator().manual_seed(0)
    lower, upper = (torch.as_tensor(a) for a in robot.finger_limits)
    fingers = lower + (upper - lower) * torch.rand(lower.shape, generator=gen, dtype=torch.float64)
    home = robot.home_posture()
    body = home.body
    if robot.has_body:
        lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
        body = lo + (hi - lo) * torch.rand(lo.shape, generator=gen, dtype=torch.float64)
    palm = torch.tensor([0.1, -0.2, 0.3, 0.4, -0.5, 0.6], dtype=torch.float64) if not robot.has_body else home.palm_pose
    model, built = _frames_agree(robot, gt.Posture(palm, fingers, body), pinch[0].object)
    assert model.nu == robot.n_finger_joints  # one actuator per finger joint; the arm's locked
    assert set(built.targets) == set(built.start)


@needs_mujoco
def test_model_of_mimic_prismatic_and_mesh_links(tmp_path, pinch):
    """A mimic joint is an equality on its leader (no actuator); a prismatic joint slides; a mesh
    link is its hull; the frames are the package's."""
    odd = gt.load_robot(write_oddhand(tmp_path / "odd"))
    q = torch.as_tensor(odd.finger_limits[1]) * 0.5
    posture = gt.Posture(torch.tensor([0.0, 0.0, 0.2, 0.1, 0.2, 0.3], dtype=torch.float64), q, torch.zeros(0))
    model, built = _frames_agree(odd, posture, pinch[0].object)
    assert model.neq == len(MIMIC) and "index_dip" not in built.targets and "index_dip" in built.start
    write_box_mesh(tmp_path / "mesh" / "palm.obj")
    meshy = gt.load_robot(write_robot(tmp_path / "mesh", mesh_hand_urdf('<mesh filename="palm.obj"/>')))
    model, _ = _frames_agree(meshy, meshy.home_posture(), pinch[0].object)
    assert model.nmesh == 1


@needs_mujoco
@pytest.mark.skipif(importlib.util.find_spec("robot_properties_fingers") is None,
                    reason="the TriFinger URDF needs the 'robot_properties_fingers' package")
def test_the_urdfs_inertials_are_the_models_mass_and_inertia(tmp_path, pinch):
    """TriFinger's links carry inertials (one turned here by rpy 0.3 0.2 0.1): the model compiles,
    and each body's mass and inertia tensor, in the body's axes, are the URDF's."""
    import mujoco
    import yaml
    from scipy.spatial.transform import Rotation

    from graspnet_torch.paths import repo_root

    example = repo_root() / "examples" / "trifinger" / "trifinger.yaml"
    urdf = Path(importlib.util.find_spec("robot_properties_fingers").submodule_search_locations[0])
    text = (urdf / "urdf" / "pro" / "trifingerpro.urdf").read_text()
    turned = '<origin rpy="0.3 0.2 0.1" xyz="0.006 0.122 0.000"/>'
    text = text.replace('<origin rpy="0 0 0" xyz="0.006 0.122 0.000"/>', turned, 1)
    assert turned in text
    (tmp_path / "trifinger.urdf").write_text(text)
    cfg = yaml.safe_load(example.read_text())
    cfg["urdf"] = str(tmp_path / "trifinger.urdf")
    (tmp_path / "trifinger.yaml").write_text(yaml.safe_dump(cfg))
    robot = gt.load_robot(tmp_path / "trifinger.yaml")
    model, _ = _frames_agree(robot, robot.home_posture(), pinch[0].object)
    checked = 0
    for link in robot.urdf.robot.links:
        inertial = link.inertial
        if inertial is None or not inertial.mass:
            continue
        i = inertial.inertia
        R = Rotation.from_euler("xyz", inertial.origin.rpy).as_matrix()
        want = R @ np.array([[i.ixx, i.ixy, i.ixz], [i.ixy, i.iyy, i.iyz], [i.ixz, i.iyz, i.izz]]) @ R.T
        body = model.body(link.name).id
        Q = np.zeros(9)
        mujoco.mju_quat2Mat(Q, model.body_iquat[body])
        Q = Q.reshape(3, 3)
        assert model.body_mass[body] == pytest.approx(inertial.mass)
        np.testing.assert_allclose(Q @ np.diag(model.body_inertia[body]) @ Q.T, want, atol=1e-9)
        np.testing.assert_allclose(model.body_ipos[body], inertial.origin.xyz, atol=1e-9)
        checked += 1
    assert checked >= 12
