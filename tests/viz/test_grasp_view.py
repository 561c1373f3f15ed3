"""The viewer's grasps on chosen contacts (graspnet_torch.viz.grasp_view): the friction cones it
draws, and a result without grasps refused in one line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.collision.surface import surface_distance, surface_normals
from graspnet_torch.viz.grasp_view import CONE_HEIGHT_M, cone_mesh
from graspnet_torch.viz.viewer import load_view

CUBE = gt.GraspProblem.from_mapping({"robot": "hand", "contacts": "auto",
                                     "object": {"shape": "box", "size": [0.06, 0.06, 0.06],
                                                "pose": [0, 0, 0.2, 0, 0, 30]}}, "cube.yaml")


@pytest.mark.parametrize("mu", [0.3, 0.6, 1.0])
def test_a_friction_cone_opens_at_atan_mu_out_of_the_object(mu):
    """Apex on the contact, every rim vertex atan(mu) from the outward normal and CONE_HEIGHT_M
    along it, nothing but the apex inside the object; its faces use every vertex."""
    contact = np.array([0.03, 0.01, 0.2])  # on the turned cube's face? pulled onto it below
    obj = CUBE.object
    contact = contact - surface_distance(obj, contact[None])[0] * surface_normals(obj, contact[None])[0]
    inward = -surface_normals(obj, contact[None])[0]
    vertices, faces = cone_mesh(contact, inward, mu)
    assert np.allclose(vertices[0], contact)
    rim = vertices[1:-1] - contact
    along = rim @ -inward
    assert np.allclose(along, CONE_HEIGHT_M, atol=1e-12)
    angle = np.arctan2(np.linalg.norm(rim - np.outer(along, -inward), axis=1), along)
    assert np.allclose(angle, math.atan(mu), atol=1e-9)
    assert np.all(surface_distance(obj, vertices[1:]) > 0)  # drawn outside, where it shows
    assert faces.max() == len(vertices) - 1 and set(faces.ravel()) == set(range(len(vertices)))


def test_a_result_without_grasps_is_refused_in_one_line(tmp_path):
    problem = tmp_path / "cube.yaml"
    problem.write_text("robot: hand\nobject: {shape: box, size: [0.06, 0.06, 0.06], pose: [0, 0, 0.2, 0, 0, 0]}\n"
                       "contacts: auto\n")
    (tmp_path / "result.json").write_text(json.dumps({"problem": "cube.yaml", "success": False, "grasps": [],
                                                      "reason": "no grasp found"}))
    with pytest.raises(gt.ProblemError, match=r"no grasps to show \(no grasp found\)") as info:
        load_view(tmp_path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("broken", "message"), [
    ("joints", r"a grasp does not fit robot 'hand'"),
    ("contacts_world", r"grasps\[0\] has no contacts_world"),
])
def test_a_grasp_that_does_not_fit_is_refused_in_one_line(tmp_path, broken, message):
    """A grasp whose joints do not fit the robot, or without its contacts: one line, naming it."""
    problem = tmp_path / "cube.yaml"
    problem.write_text("robot: hand\nobject: {shape: box, size: [0.06, 0.06, 0.06], pose: [0, 0, 0.2, 0, 0, 0]}\n"
                       "contacts: auto\n")
    grasp = gt.solve("glass3", trials=1, seed=0, solver={"max_iterations": 2}).best.to_dict()
    grasp["contacts_world"] = [[0.03, 0.0, 0.2], [-0.03, 0.0, 0.2]]
    grasp[broken] = {} if broken == "joints" else None
    (tmp_path / "result.json").write_text(json.dumps({"problem": "cube.yaml", "success": True, "grasps": [grasp]}))
    with pytest.raises(gt.ProblemError, match=message) as info:
        load_view(tmp_path)
    assert "\n" not in str(info.value)
