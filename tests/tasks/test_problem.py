"""Problem files: the valid ones load, every shipped task is reachable, bad ones are refused."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.robot import load_robot_cfg

GOOD = {"robot": "hand",
        "object": {"shape": "cylinder", "size": [0.035, 0.12], "pose": [0.0, 0.0, 0.06, 0, 0, 90]},
        "contacts": [{"finger": "thumb", "position": [0.035, 0.0, 0.02]},
                     {"finger": "index", "position": [-0.03, 0.018, 0.03]}]}


def _write(tmp_path, data, name="p.yaml"):
    import yaml

    path = tmp_path / name
    path.write_text(json.dumps(data) if name.endswith(".json") else yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("name", ["p.yaml", "p.json"])
def test_valid_problem_file(tmp_path, name):
    p = gt.GraspProblem.from_file(_write(tmp_path, GOOD, name))
    assert p.robot == "hand" and p.fingers == ("thumb", "index")
    np.testing.assert_allclose(p.object.pose[3:], [0, 0, math.pi / 2])
    world = p.contacts_world()  # rotated 90 deg about z, then lifted
    np.testing.assert_allclose(world[0], [0.0, 0.035, 0.08], atol=1e-12)
    assert p.palm_bounds is None and p.bounds() is None  # the search space follows the contacts
    robot_box = gt.GraspProblem.from_mapping({**GOOD, "palm_bounds": "robot"})
    np.testing.assert_allclose(robot_box.bounds().lower, load_robot_cfg("hand").palm_bounds.lower)
    assert robot_box.to_mapping()["palm_bounds"] == "robot"


@pytest.mark.parametrize("task", ["block5", "glass3", "glass4", "videotape5"])
def test_shipped_task_is_reachable(hand, task):
    """Its reference posture puts every fingertip on its contact, within bounds and limits."""
    p = gt.GraspProblem.from_task(task)
    ref = p.reference
    bounds = p.bounds()
    assert bool(np.all(ref.palm_pose >= bounds.lower) and np.all(ref.palm_pose <= bounds.upper))
    q = hand.home_posture().fingers.clone()
    lo, hi = hand.finger_limits
    for f, v in ref.joints.items():
        k = hand.finger_index(f)
        assert bool(np.all(v >= lo[k] - 1e-9) and np.all(v <= hi[k] + 1e-9)), f
        q[k] = torch.as_tensor(v)
    tips = hand.fingertips_world(torch.as_tensor(ref.palm_pose), q)[[hand.finger_index(f) for f in p.fingers]]
    err = torch.linalg.vector_norm(tips - torch.as_tensor(p.contacts_world()), dim=-1)
    assert float(err.max()) < 2e-4
    # contacts lie on the object's surface
    mesh = p.object.trimesh()
    import trimesh

    d = np.abs(trimesh.proximity.signed_distance(mesh, p.contacts_world()))
    assert float(d.max()) < 1.5e-3  # the cylinder is a 48-gon


@pytest.mark.parametrize("task", ["env1", "env2", "fig10"])
@pytest.mark.slow
def test_arm_task_has_a_collision_free_reachable_reference(robots, task):
    """Each arm task's reference (arm joints within the task's bounds, finger joints within
    limits) puts every fingertip on its contact, and FCL finds no collision: the task is
    solvable collision-free. The obstacles neither touch the object nor swallow a contact."""
    import fcl

    from graspnet_torch.collision import CollisionScene
    from graspnet_torch.solver.api import reference_posture
    from graspnet_torch.solver.arm import arm_bounds

    arm = robots["arm_hand"]
    p = gt.GraspProblem.from_task(task)
    assert p.robot == "arm_hand" and p.obstacles and p.object is not None
    ref = reference_posture(arm, p)
    lo, hi = arm_bounds(arm, p)
    assert bool(np.all(ref.body.numpy() >= lo) and np.all(ref.body.numpy() <= hi))
    flo, fhi = arm.finger_limits
    assert bool(np.all(ref.fingers.numpy() >= flo - 1e-9) and np.all(ref.fingers.numpy() <= fhi + 1e-9))
    idx = [arm.finger_index(f) for f in p.fingers]
    tips = arm.fingertips_world_from_body(ref.body, ref.fingers)[idx]
    assert float(torch.linalg.vector_norm(tips - torch.as_tensor(p.contacts_world()), dim=-1).max()) < 1e-5
    scene = CollisionScene(arm, p)
    assert scene.check(ref).count == 0
    for k, obstacle in enumerate(scene.obstacles):
        assert not fcl.collide(obstacle, scene.object, fcl.CollisionRequest(), fcl.CollisionResult()), k
    for o in p.obstacles:
        assert not o.trimesh().contains(p.contacts_world()).any()  # no obstacle swallows a contact


@pytest.mark.parametrize(("change", "message"), [
    ({"robot": "robonaut"}, r"robot: unknown robot 'robonaut'"),
    ({"robot": 3}, r"'robot' must name a robot"),
    ({"contacts": [{"finger": "thumb", "position": [0, 0, 0]}]}, r"need 2 to 5 contacts.*got 1"),
    ({"contacts": [{"finger": f, "position": [0, 0, 0]}
                   for f in ("thumb", "index", "middle", "ring", "pinky", "thumb")]},
     r"need 2 to 5 contacts.*got 6"),
    ({"contacts": [{"finger": "thumb", "position": [0, 0, 0]}, {"finger": "little", "position": [0, 0, 0]}]},
     r"contacts\[1\].finger: unknown finger 'little' for robot 'hand' \(fingers: thumb, index, middle, ring, pinky\)"),
    ({"contacts": [{"finger": "index", "position": [0, 0, 0]}, {"finger": "index", "position": [0, 0, 1]}]},
     r"contacts\[1\].finger: finger 'index' appears twice \(contacts\[0\] and contacts\[1\]\)"),
    ({"contacts": [{"finger": "thumb", "position": [0, 0, ".nan"]}, {"finger": "index", "position": [0, 0, 0]}]},
     r"contacts\[0\].position\[2\]: nan is not a finite number"),
    ({"contacts": [{"finger": "thumb", "position": [0, 0]}, {"finger": "index", "position": [0, 0, 0]}]},
     r"contacts\[0\].position: expected 3 numbers"),
    ({"palm_bounds": {"min": [0, 0, 0, 0, 0, 10], "max": [1, 1, 1, 1, 1, 0]}}, r"palm_bounds: min > max for rz"),
    ({"object": {"shape": "torus", "size": [1], "pose": [0] * 6}}, r"object.shape: expected box, cylinder, sphere"),
    ({"object": {"shape": "box", "size": [0.1, 0.1], "pose": [0] * 6}}, r"object.size: expected 3 numbers"),
    ({"object": {"shape": "sphere", "size": [-0.1], "pose": [0] * 6}}, r"object.size: dimensions must be positive"),
    ({"contact": []}, r"unknown key\(s\) contact"),
])
def test_bad_problem_is_refused_with_one_clear_line(tmp_path, change, message):
    data = {**GOOD, **change}
    if "contact" in change:
        data = {**GOOD, "contact": []}
    text = json.dumps(data).replace('".nan"', "NaN")
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(gt.ProblemError, match=message) as info:
        gt.GraspProblem.from_file(path)
    assert "\n" not in str(info.value) and "bad.json" in str(info.value)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(gt.ProblemError, match=r"problem file not found: .*nope.yaml"):
        gt.GraspProblem.from_file(tmp_path / "nope.yaml")
    (tmp_path / "m.yaml").write_text("robot: hand\ncontacts: [\n")
    with pytest.raises(gt.ProblemError, match=r"m.yaml: malformed YAML \(line \d+"):
        gt.GraspProblem.from_file(tmp_path / "m.yaml")
    (tmp_path / "m.json").write_text('{"robot": "hand",')
    with pytest.raises(gt.ProblemError, match=r"m.json: malformed JSON \(line 1"):
        gt.GraspProblem.from_file(tmp_path / "m.json")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(gt.ProblemError, match=r"must be a mapping"):
        gt.GraspProblem.from_file(tmp_path / "list.yaml")


def test_unknown_task():
    with pytest.raises(gt.ProblemError, match=r"unknown task 'bottle'.*glass3"):
        gt.GraspProblem.from_task("bottle")


def test_round_trip_through_mapping(tmp_path):
    p = gt.GraspProblem.from_task("videotape5")
    again = gt.GraspProblem.from_mapping(p.to_mapping(), source="again")
    np.testing.assert_allclose(again.contacts_world(), p.contacts_world())
    assert again.fingers == p.fingers


FINGERS = {f: [0, 0, 0, 0] for f in ("thumb", "index", "middle")}


@pytest.mark.parametrize(("reference", "message"), [
    ({"palm_pose": [0, 0, 0, 0, 0, 0], "joints": {"thumb": [0, 0, 0, 0]}}, r"reference: expected \{arm_joints"),
    ({"arm_joints": [1, 2], "joints": FINGERS}, r"reference.arm_joints: expected a mapping"),
    ({"arm_joints": {"elbow_flexion": "x"}, "joints": FINGERS}, r"reference.arm_joints\[0\]"),
])
def test_bad_arm_references_are_refused(reference, message):
    """Malformed arm references are refused (FINGERS: every contact finger given)."""
    import yaml

    from graspnet_torch.paths import configs_dir

    data = yaml.safe_load((configs_dir() / "task" / "env1.yaml").read_text())
    data["reference"] = reference
    with pytest.raises(gt.ProblemError, match=message):
        gt.GraspProblem.from_mapping(data, source="env1")


def test_an_arm_reference_with_an_unknown_joint_is_refused(robots):
    import yaml

    from graspnet_torch.paths import configs_dir
    from graspnet_torch.solver.api import reference_posture

    data = yaml.safe_load((configs_dir() / "task" / "env1.yaml").read_text())
    data["reference"]["arm_joints"]["knee"] = 10.0
    problem = gt.GraspProblem.from_mapping(data, source="env1")
    with pytest.raises(gt.ProblemError, match=r"reference.arm_joints: unknown joint\(s\) knee of robot 'arm_hand'"):
        reference_posture(robots["arm_hand"], problem)


KIND_VALUES = {"contacts": [{"finger": "thumb", "position": [0, 0, 0.2]}], "points": [[0, 0, 0], [0, 0, 0.1]],
               "approach": {"x": 0.0}, "palm_bounds": {"min": [0] * 6, "max": [1] * 6},
               "bounds": {"min": [0], "max": [1]}, "reference": {"palm_pose": [0] * 6, "joints": {}}}


@pytest.mark.parametrize("robot", ["hand", "arm_hand", "manus"])
def test_a_key_of_another_kind_of_robot_is_refused_by_its_schema(robot):
    """Every kind-specific key a robot's schema lacks is refused with one line naming it and what
    the robot's problems give; the schema's own target key is the one problems need."""
    from graspnet_torch.robot.config import load_robot_cfg

    cfg = load_robot_cfg(robot)
    schema = cfg.problem_schema
    assert schema.targets == ("points" if cfg.kind == "gripper" else "contacts")
    foreign = [k for k in KIND_VALUES if k not in schema.keys]
    assert foreign  # every kind lacks some
    for key in foreign:
        data = {"robot": robot, schema.targets: KIND_VALUES[schema.targets], key: KIND_VALUES[key]}
        with pytest.raises(gt.ProblemError, match=rf"'{key}' \(.+\) does not apply to robot '{robot}' "
                                                  rf"\({cfg.kind}\), whose problems give {schema.targets}"):
            gt.GraspProblem.from_mapping(data)


def test_a_shape_made_in_python_from_lists_round_trips():
    """A shape made from plain lists (a Python caller's) holds its pose as an array, as one read from
    a file does, and writes and reads back the same."""
    made = gt.Shape("box", [0.05, 0.04, 0.03], [0.0, 0.0, 0.2, 0.0, 0.0, 0.5])
    assert isinstance(made.pose, np.ndarray) and made.size == (0.05, 0.04, 0.03)
    again = gt.Shape.from_mapping(made.to_mapping(), "test")
    assert again.kind == "box" and again.size == made.size
    np.testing.assert_allclose(again.pose, made.pose, atol=1e-12)
    mesh = gt.Shape("mesh", (), [0, 0, 0.2, 0, 0, 0], "cup.obj", 0.001)
    assert mesh.mesh == Path("cup.obj") and mesh.pose.dtype == np.float64
