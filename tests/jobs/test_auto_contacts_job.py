"""scripts/solve_grasp.py on a ``contacts: auto`` problem: contacts chosen on the object, the
grasps written and re-checked independently; a bad one refused before anything is written."""

from __future__ import annotations

import json

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.collision.surface import surface_distance
from graspnet_torch.jobs.solve_many import prepare_job, run_job
from graspnet_torch.viz.viewer import load_view, serve

PROBLEM = """robot: hand
object: {shape: box, size: [0.06, 0.06, 0.06], pose: [0, 0, 0.2, 0, 0, 0]}
contacts: auto
fingers: [thumb, index, middle]
grasps: 1
"""


@pytest.mark.slow
def test_auto_problem_gives_grasps_on_the_objects_surface(tmp_path):
    problem = tmp_path / "cube.yaml"
    problem.write_text(PROBLEM)
    out = tmp_path / "result.json"
    run_job({"problem": str(problem), "out": str(out), "seed": 0, "trials": 8}, tmp_path / "run")
    data = json.loads(out.read_text())
    assert data["auto"] == {"fingers": ["thumb", "index", "middle"], "grasps": 1}
    assert data["success"] == bool(data["grasps"]) and len(data["grasps"]) <= 1
    if data["grasps"]:  # the top level is the best grasp: its contacts, pads and postures
        best = data["grasps"][0]
        assert all(data[k] == best[k] for k in ("contacts", "palm_pose", "joints", "squeeze", "quality"))
    obj = gt.GraspProblem.from_file(problem).object
    for g in data["grasps"]:
        contacts = np.asarray(g["contacts_world"])
        assert np.all(np.abs(surface_distance(obj, contacts)) < 1e-3)  # on the cube's surface
        assert g["success"] and g["penetration_mm"] <= 1.0
        assert max(g["pad_distance_mm"].values()) <= 1.0
        assert max(g["normal_angle_deg"].values()) <= 30.0 + 1e-6
        if data["physics_checked"]:
            assert g["holds"] == sum(g["physics"]["directions"].values())
    assert (tmp_path / "run" / "grasps.png").is_file() == bool(data["grasps"])  # the grasps side by side
    if data["grasps"]:  # the viewer shows the grasps with their contacts and friction cones
        view = load_view(out)
        assert len(view.postures) == len(view.cones) == len(data["grasps"])
        for (contacts, inward), g in zip(view.cones, data["grasps"], strict=True):
            np.testing.assert_allclose(contacts, g["contacts_world"])
            assert np.all(surface_distance(obj, contacts + 0.002 * inward) < 0)  # the normals point in
        serve(view, port=8141).stop()  # the scene is built (the page itself: tests/viz/test_viewer.py)


def test_a_bad_auto_problem_is_refused_before_anything_is_written(tmp_path):
    problem = tmp_path / "bad.yaml"
    problem.write_text(PROBLEM.replace("fingers: [thumb, index, middle]", "fingers: [thumb, toe]"))
    out = tmp_path / "result.json"
    with pytest.raises(gt.ProblemError, match=r"fingers: unknown finger\(s\) toe"):
        prepare_job({"problem": str(problem), "out": str(out)}, tmp_path / "run")
    assert not out.exists()
