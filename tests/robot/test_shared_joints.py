"""Hands whose fingers share joints (graspnet_torch/robot/shared.py): found from the URDF alone,
each finger's own chain starting after them, base frames against pytorch-kinematics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.chain import UrdfModel
from graspnet_torch.robot.shared import find_shared_joints
from tests.odd_hands import COUPLED_TIPS, assert_jacobian_matches_fd, coupled_hand_urdf, urdf_joint, write_coupled_hand


def test_shared_joints_are_found_from_the_urdf(tmp_path):
    write_coupled_hand(tmp_path)
    shared = find_shared_joints(UrdfModel(tmp_path / "coupled.urdf"), "palm", COUPLED_TIPS)
    assert shared.names == ("hub", "spread")
    assert shared.followers == {"d_spread": ("spread", 0.5, 0.0)}
    assert shared.bases == {"a": "hub", "b": "hub", "c": "c0", "d": "d0", "e": "palm"}
    np.testing.assert_allclose(shared.lower, [-0.4, 0.0])
    np.testing.assert_allclose(shared.upper, [0.6, 0.6])  # d_spread's 0.3 limit at x0.5 allows 0.6


def test_a_finger_own_joint_before_a_shared_one_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="finger 'f': its own joint 'f_own' comes before joint 'f_spread'"):
        gt.load_robot(write_coupled_hand(tmp_path, bad=True))


def test_base_frames_agree_with_pytorch_kinematics(tmp_path):
    """Each finger's base in the palm, for random shared joints (followers from the URDF's own
    numbers), against pytorch-kinematics on the whole URDF."""
    import pytorch_kinematics as pk

    write_coupled_hand(tmp_path)
    shared = find_shared_joints(UrdfModel(tmp_path / "coupled.urdf"), "palm", COUPLED_TIPS)
    g = torch.Generator().manual_seed(0)
    s = shared.lower + (shared.upper - shared.lower) * torch.rand(16, 2, generator=g, dtype=torch.float64).numpy()
    frames = shared.base_frames(torch.as_tensor(s))
    chain = pk.build_chain_from_urdf((tmp_path / "coupled.urdf").read_bytes()).to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    th = torch.zeros(16, len(names), dtype=torch.float64)
    th[:, names.index("hub")] = torch.as_tensor(s[:, 0])
    th[:, names.index("spread")] = torch.as_tensor(s[:, 1])
    th[:, names.index("d_spread")] = 0.5 * torch.as_tensor(s[:, 1])
    fk = chain.forward_kinematics(th)
    assert set(frames) == {"a", "b", "c", "d"}
    for finger, base in shared.bases.items():
        if finger in frames:
            want = torch.linalg.solve(fk["palm"].get_matrix(), fk[base].get_matrix())
            torch.testing.assert_close(frames[finger], want, atol=1e-7, rtol=0)  # pk parses origins in float32


def test_the_robot_holds_shared_joints_at_home_and_its_fingertips_agree_with_the_urdf(tmp_path):
    """Each finger's own chain starts after the shared joints (its free joints only); with the
    shared joints at their home (10 and 20 degrees), the fingertips from the robot's finger
    kinematics equal pytorch-kinematics on the whole URDF (mimic joints from the URDF), and the
    Jacobians equal finite differences."""
    import pytorch_kinematics as pk

    robot = gt.load_robot(write_coupled_hand(tmp_path))
    assert robot.shared.names == ("hub", "spread")
    np.testing.assert_allclose(robot.shared_reference, np.radians([10.0, 20.0]))
    assert {f.name: f.chain.joint_names for f in robot.fingers.values()} == {
        "a": ("a_mcp", "a_pip"), "b": ("b_mcp", "b_pip"), "c": ("c_mcp", "c_pip"), "d": ("d_mcp",),
        "e": ("e_cmc", "e_mcp")}
    lo, hi = (torch.as_tensor(x) for x in robot.finger_limits)
    q = lo + (hi - lo) * torch.rand(8, *lo.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    got = robot.fingertips_palm(q)
    chain = pk.build_chain_from_urdf((tmp_path / "coupled.urdf").read_bytes()).to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    th = torch.zeros(8, len(names), dtype=torch.float64)
    values = {"hub": np.radians(10.0), "spread": np.radians(20.0), "d_spread": 0.5 * np.radians(20.0)}
    for name, v in values.items():
        th[:, names.index(name)] = v
    for k, f in enumerate(robot.fingers.values()):
        for i, name in enumerate(f.chain.joint_names):
            th[:, names.index(name)] = q[:, k, i]
    th[:, names.index("d_pip")] = 1.2 * th[:, names.index("d_mcp")]
    fk = chain.forward_kinematics(th)
    want = torch.stack([torch.linalg.solve(fk["palm"].get_matrix(), fk[f.chain.tip].get_matrix())[:, :3, 3]
                        for f in robot.fingers.values()], dim=1)
    torch.testing.assert_close(got, want, atol=1e-7, rtol=0)  # pk parses origins in float32
    assert_jacobian_matches_fd(robot, q, atol=1e-7)
    values = robot.joint_values(robot.home_posture())  # results and pictures see the shared joints where held
    assert values["hub"] == pytest.approx(np.radians(10.0)) and values["d_spread"] == pytest.approx(np.radians(10.0))


@pytest.mark.parametrize("name", ["hand", "arm_hand", "manus", "examples/trifinger/trifinger.yaml"])
def test_robots_without_shared_joints_have_none(name):
    robot = gt.load_robot(name if "/" not in name else repo_root() / name)
    assert robot.shared.names == () and robot.shared.paths == {}


SVH = repo_root() / "examples/schunk_svh/dex-urdf/robots/hands/schunk_hand/schunk_svh_hand_right.urdf"


@pytest.mark.skipif(not SVH.is_file(), reason="the Schunk SVH URDF is not fetched (examples/schunk_svh/*.yaml)")
def test_the_schunk_svh_loads_by_config_alone():
    robot = gt.load_robot(repo_root() / "examples/schunk_svh/schunk_svh_right.yaml")
    assert robot.shared.names == ("right_hand_Thumb_Opposition", "right_hand_Finger_Spread")
    assert robot.shared.bases["little"] == "right_hand_virtual_i" and robot.shared.bases["middle"] == \
        "right_hand_base_link"
    assert [f.n_joints for f in robot.fingers.values()] == [1, 2, 2, 1, 1]


@pytest.mark.slow
def test_a_solve_searches_the_shared_joints_and_checks_from_the_urdf_alone(tmp_path):
    """Contacts from a random posture of the whole coupled hand (its shared joints away from
    home): solved to < 1 mm by searching the shared joints with the palm pose; the reported joint
    lists (palm to tip, shared and mimic joints included) placed into pytorch-kinematics on the
    URDF alone give the reported fingertip errors, every follower at multiplier x leader (1e-9)."""
    import pytorch_kinematics as pk

    from graspnet_torch.fcnn.train import FCNNTrainCfg
    from graspnet_torch.jobs.train_fcnn import train_fcnn
    from graspnet_torch.robot.transforms import pose_to_matrix_np

    robot = gt.load_robot(write_coupled_hand(tmp_path))
    tiny = FCNNTrainCfg(epochs=3, targets_per_epoch=64, train_steps=10, batch_size=64, val_targets=200, val_every=2)
    ik, _ = train_fcnn(robot, tiny, tmp_path / "run", progress=False, eval_targets=100)
    problem = gt.random_reachable_problem(robot, 3, n_fingers=4)
    result = gt.solve(problem, trials=8, seed=0, robot=robot, finger_ik=ik)
    assert result.success, result.best.total_error_mm
    out = result.to_dict()
    chain = pk.build_chain_from_urdf((tmp_path / "coupled.urdf").read_bytes()).to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    values = {}
    for finger, row in out["joints"].items():
        listed = robot.finger_all_joint_names(finger)
        assert len(row) == len(listed)
        for name, v in zip(listed, row, strict=True):
            assert values.setdefault(name, np.radians(v)) == pytest.approx(np.radians(v), abs=1e-12)  # once per chain
    assert values["d_spread"] == pytest.approx(0.5 * values["spread"], abs=1e-9)
    assert values["d_pip"] == pytest.approx(1.2 * values["d_mcp"], abs=1e-9)
    assert abs(values["hub"] - np.radians(10.0)) > 1e-3 or abs(values["spread"] - np.radians(20.0)) > 1e-3
    th = torch.tensor([[values.get(n, 0.0) for n in names]], dtype=torch.float64)
    fk = chain.forward_kinematics(th)
    pose = np.asarray(out["palm_pose"], dtype=np.float64)
    palm = fk["palm"].get_matrix()[0].numpy()
    world = pose_to_matrix_np(np.concatenate([pose[:3], np.radians(pose[3:])])) @ np.linalg.inv(palm)
    for contact, target in zip(problem.contacts, problem.contacts_world(), strict=True):
        tip = (world @ fk[COUPLED_TIPS[contact.finger]].get_matrix()[0].numpy())[:3, 3]
        assert np.linalg.norm(tip - target) * 1000 == pytest.approx(out["fingertip_error_mm"][contact.finger],
                                                                    abs=1e-3)  # 1e-6 m (pk: float32 origins)


def write_coupled_arm(folder: Path) -> Path:
    """The coupled hand on a 3-joint arm (torso -> palm), in one URDF."""
    folder.mkdir(parents=True, exist_ok=True)
    hand = coupled_hand_urdf()
    body = hand[hand.index("<link"):hand.rindex("</robot>")]
    arm = ['<link name="torso"/>', '<link name="upper"/>', '<link name="fore"/>',
           urdf_joint("shoulder", "revolute", "torso", "upper", "0 0 0.5", axis="0 0 1", lim=(-1.5, 1.5)),
           urdf_joint("elbow", "revolute", "upper", "fore", "0 0 0.3", axis="0 1 0", lim=(-1.5, 1.5)),
           urdf_joint("wrist", "revolute", "fore", "palm", "0 0 0.25", axis="1 0 0", lim=(-1.5, 1.5))]
    (folder / "coupled_arm.urdf").write_text('<robot name="coupled_arm">\n' + "\n".join(arm) + body + "</robot>\n")
    cfg = {"name": "coupled_arm", "urdf": "coupled_arm.urdf", "palm_link": "palm",
           "fingers": {f: {"tip": tip} for f, tip in COUPLED_TIPS.items()}, "arm": {"base": "torso", "tip": "palm"}}
    path = folder / "coupled_arm.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


@pytest.mark.slow
def test_an_arm_searches_the_shared_joints_with_its_own(tmp_path):
    """The coupled hand on an arm: contacts from a random posture (arm, fingers and shared joints
    drawn within their limits) are reached, the arm joints and the shared joints reported, and the
    fingertips of the reported posture (forward kinematics of every listed joint) are the
    reported errors."""
    from graspnet_torch.fcnn.train import FCNNTrainCfg
    from graspnet_torch.jobs.train_fcnn import train_fcnn
    from graspnet_torch.solver.postures import trial_posture

    robot = gt.load_robot(write_coupled_arm(tmp_path))
    tiny = FCNNTrainCfg(epochs=3, targets_per_epoch=64, train_steps=10, batch_size=64, val_targets=200, val_every=2)
    ik, _ = train_fcnn(robot, tiny, tmp_path / "run", progress=False, eval_targets=100)
    g = torch.Generator().manual_seed(4)
    lo, hi = (torch.as_tensor(a) for a in robot.body_limits)
    body = lo + (hi - lo) * torch.rand(lo.shape, generator=g, dtype=torch.float64)
    flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
    q = flo + (fhi - flo) * torch.rand(flo.shape, generator=g, dtype=torch.float64)
    s = torch.as_tensor(robot.shared.lower + (robot.shared.upper - robot.shared.lower) * np.array([0.8, 0.9]))
    R, t = robot.palm_frame(body)
    tips = (R @ robot.fingertips_palm(q, s).unsqueeze(-1)).squeeze(-1) + t
    problem = gt.GraspProblem.from_mapping(
        {"robot": "coupled_arm", "contacts": [{"finger": f, "position": tips[robot.finger_index(f)].tolist()}
                                              for f in ("a", "c", "d")]},
        robot_cfg=robot.cfg, source="coupled arm problem")
    result = gt.solve(problem, trials=8, seed=0, robot=robot, finger_ik=ik)
    assert result.success, result.best.total_error_mm
    posture = trial_posture(robot, result.best)
    assert posture.shared is not None and set(result.best.arm_joints) == {"shoulder", "elbow", "wrist"}
    R, t = robot.palm_frame(posture.body)
    got = (R @ robot.fingertips_palm(posture.fingers, posture.shared).unsqueeze(-1)).squeeze(-1) + t
    for contact, target in zip(problem.contacts, problem.contacts_world(), strict=True):
        err = float(np.linalg.norm(got[robot.finger_index(contact.finger)].numpy() - target)) * 1000
        assert err == pytest.approx(result.best.fingertip_error_mm[contact.finger], abs=1e-6)
