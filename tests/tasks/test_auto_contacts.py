"""``contacts: auto`` problems: read and checked (graspnet_torch.tasks.auto_contacts), refused by
the solver, which needs contacts."""

from __future__ import annotations

import dataclasses

import pytest

import graspnet_torch as gt
from graspnet_torch.robot import load_robot_cfg
from graspnet_torch.tasks.auto_contacts import AutoContacts

CUBE = {"shape": "box", "size": [0.06, 0.06, 0.06], "pose": [0, 0, 0.2, 0, 0, 0]}


def _problem(**keys) -> gt.GraspProblem:
    return gt.GraspProblem.from_mapping({"robot": "hand", "object": CUBE, "contacts": "auto", **keys}, "p.yaml")


def test_auto_problem_reads_fingers_in_robot_order_and_grasps():
    p = _problem(fingers=["middle", "thumb", "index"], grasps=3)
    assert p.auto == AutoContacts(("thumb", "index", "middle"), 3)
    assert p.contacts == () and p.object.kind == "box"


def test_auto_problem_defaults_and_counts():
    assert _problem().auto.fingers == ("thumb", "index", "middle") and _problem().auto.grasps == 5
    assert _problem(fingers=4).auto.fingers == ("thumb", "index", "middle", "ring")
    assert _problem(n_fingers=4).auto == _problem(fingers=4).auto  # n_fingers: N is fingers: N


@pytest.mark.parametrize(("keys", "message"), [
    ({"fingers": 7}, r"p\.yaml: fingers: 7: robot 'hand' has 5 fingers"),
    ({"fingers": 1}, r"fingers: 1: robot 'hand' has 5 fingers"),
    ({"fingers": ["thumb", "toe"]}, r"fingers: unknown finger\(s\) toe"),
    ({"fingers": ["thumb", "thumb"]}, r"fingers: need 2 or more different fingers"),
    ({"fingers": "thumb"}, r"fingers: expected a list of finger names or a number"),
    ({"n_fingers": 6}, r"p\.yaml: n_fingers: 6: robot 'hand' has 5 fingers"),
    ({"n_fingers": ["thumb", "index"]}, r"n_fingers: expected a number of fingers"),
    ({"n_fingers": 2, "fingers": ["thumb", "index"]}, r"fingers and n_fingers: give one"),
    ({"grasps": 0}, r"p\.yaml: grasps: expected a whole number from 1 to 100"),
    ({"grasps": 101}, r"grasps: expected a whole number from 1 to 100"),
    ({"grasps": True}, r"grasps: expected a whole number"),
    ({"object": None}, r"contacts: auto needs an object"),
    ({"obstacles": [{"shape": "box", "size": [0.1], "pose": [0.3, 0, 0, 0, 0, 0]}]},
     r"p\.yaml: obstacles\[0\]\.size: expected 3 numbers"),
])
def test_bad_auto_problems_are_refused_in_one_line(keys, message):
    with pytest.raises(gt.ProblemError, match=message) as info:
        _problem(**keys)
    assert "\n" not in str(info.value)


def test_auto_keys_only_with_auto_contacts():
    data = {"robot": "hand", "object": CUBE, "grasps": 2,
            "contacts": [{"finger": "thumb", "position": [0.03, 0, 0]}, {"finger": "index", "position": [-0.03, 0, 0]}]}
    with pytest.raises(gt.ProblemError, match=r"grasps: only with 'contacts: auto'"):
        gt.GraspProblem.from_mapping(data, "p.yaml")


def test_auto_contacts_need_a_hand_free_or_named_by_its_arm():
    """A gripper lists no contacts (its contacts: auto chooses its two points); an arm whose config
    names no free hand cannot choose contacts; arm_hand names its hand."""
    with pytest.raises(gt.ProblemError, match=r"'contacts' \(one point per finger\) does not apply to robot 'manus' "
                                              r"\(gripper\)"):
        gt.GraspProblem.from_mapping({"robot": "manus", "object": CUBE, "contacts": [
            {"finger": "thumb", "position": [0.0, 0.0, 0.0]}]}, "p.yaml")
    gripper = gt.GraspProblem.from_mapping({"robot": "manus", "object": CUBE, "contacts": "auto"}, "p.yaml")
    assert gripper.auto == AutoContacts((), 5)  # a gripper's contacts: auto is its points: auto
    cfg = load_robot_cfg("arm_hand")
    assert cfg.hand == "hand"
    assert gt.GraspProblem.from_mapping({"robot": "arm_hand", "object": CUBE, "contacts": "auto"}, "p.yaml").auto
    nameless = dataclasses.replace(cfg, hand=None)
    with pytest.raises(gt.ProblemError, match=r"robot 'arm_hand' \(arm_hand\): contacts are chosen for a free hand"):
        gt.GraspProblem.from_mapping({"robot": "arm_hand", "object": CUBE, "contacts": "auto"}, "p.yaml",
                                     robot_cfg=nameless)


def test_the_solver_refuses_auto_contacts(tmp_path):
    path = tmp_path / "auto.yaml"
    path.write_text("robot: hand\nobject: {shape: sphere, size: [0.04], pose: [0, 0, 0.2, 0, 0, 0]}\ncontacts: auto\n")
    with pytest.raises(gt.ProblemError, match=r"contacts: auto: the solver needs contacts"):
        gt.solve(path, trials=2)
