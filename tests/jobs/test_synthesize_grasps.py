"""scripts/synthesize_grasps.py: a folder of meshes in, one result file per object and a summary out.

The job's own work (finding the meshes, placing each object, the result files, the summary, the
resume, the one-line refusals) is checked on real mesh files. The grasps themselves come from
``gt.synthesize_grasps`` on the same object as a primitive (a box, a sphere) at the pose the job
chose: on the mesh itself the same settings took 33 s (box) and 85 s (sphere) on a loaded 2-core
machine at 4ab3558 (the mesh surface queries), over this file's budget; the primitive takes seconds.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh
import yaml

import graspnet_torch as gt
import graspnet_torch.jobs.synthesize as job_module
from graspnet_torch.errors import CheckpointError, ConfigError
from graspnet_torch.jobs.synthesize import OBJECT_CENTRE, SynthesizeGraspsJobCfg, prepare_synthesize, synthesize_objects
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.robot.shape import Shape
from graspnet_torch.viz.viewer import load_view


def _objects(folder):
    """A 6 cm box (STL, its origin at a corner), a 4 cm icosphere (OBJ) and a file that is not a
    mesh (STL); a text file beside them is not read."""
    folder.mkdir(parents=True, exist_ok=True)
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    box.apply_translation((0.03, 0.03, 0.03))  # the job centres it whatever its origin
    box.export(folder / "box.stl")
    trimesh.creation.icosphere(subdivisions=3, radius=0.02).export(folder / "ball.obj")
    (folder / "broken.stl").write_text("solid nothing\nendsolid nothing\n")
    (folder / "notes.txt").write_text("not a mesh: not read")
    return folder


def _stand_in(obj: Shape) -> Shape:
    """The test meshes as primitives at the job's pose (module docstring)."""
    lo, hi = obj.trimesh().bounds
    extents = hi - lo
    centre = (lo + hi) / 2
    np.testing.assert_allclose(centre, OBJECT_CENTRE, atol=1e-9)  # the job centred the object in front of the hand
    pose = np.array([*centre, 0.0, 0.0, 0.0])
    if "box" in obj.mesh.name:
        return Shape("box", tuple(float(e) for e in extents), pose)
    return Shape("sphere", (float(extents.max() / 2),), pose)


@pytest.fixture
def primitive_synthesis(monkeypatch):
    real = gt.synthesize_grasps
    monkeypatch.setattr(job_module, "synthesize_grasps", lambda robot, obj, **kw: real(robot, _stand_in(obj), **kw))


def _settings(folder, out, **kw):
    return {"objects": str(folder), "out": str(out), "candidates": 16, "grasps": 2, "verify": "none",
            "progress": False, "scale": 1.0, "pictures": False, **kw}


def _summary(out):
    with open(out / "summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _check_results(out, physics: bool, names=("ball.obj", "box.stl", "broken.stl")):
    """summary.csv against the result files, row by row."""
    rows = {r["object"]: r for r in _summary(out)}
    assert set(rows) == set(names)
    for name, row in rows.items():
        data = json.loads((out / f"{name.rsplit('.', 1)[0]}.json").read_text())
        assert data["robot"] == "hand" and data["object"]["file"].endswith(name)
        assert int(row["grasps"]) == len(data["grasps"]) == data["summary"]["grasps"]
        if name == "broken.stl":
            assert row["reason"] and "broken.stl" in row["reason"] and not data["grasps"]
            continue
        assert not row["reason"] and data["grasps"], row
        assert {"generate_s", "solve_s", "physics_s", "solved", "succeeded"} <= set(data["stats"])
        for g in data["grasps"]:
            assert g["success"] and g["contact_model"] == "surface" and len(g["contacts_world"]) == 3
            assert [c["finger"] for c in g["contacts"]] == g["fingers"] == ["thumb", "index", "middle"]
            assert {"epsilon", "min_singular_value", "force_closure"} <= set(g["quality"])
            assert "trials" not in g and g["trials_run"] == 1 and "palm_pose" in g  # every field of a result (one
            # trial: the warm start from the sampled posture)
            assert (g["physics"] is not None) == physics
            if physics:
                assert g["physics"]["of"] == 6 and g["holds"] == g["physics"]["holds"]
        best_eps = max(g["quality"]["epsilon"] for g in data["grasps"])
        assert float(row["best_epsilon"]) == pytest.approx(best_eps)
        pen = [g["penetration_mm"] for g in data["grasps"] if "penetration_mm" in g]
        assert (float(row["deepest_penetration_mm"]) == pytest.approx(max(pen))) if pen else \
            row["deepest_penetration_mm"] == ""
        if physics:
            holds = [g["physics"]["holds"] for g in data["grasps"]]
            assert int(row["best_holds"]) == max(holds)
            assert row["top1_holds_all"] == str(holds[0] == 6)
            assert row["top5_any_holds_all"] == str(6 in holds[:5])
        else:
            assert row["best_holds"] == row["top1_holds_all"] == row["top5_any_holds_all"] == ""
    return rows


def test_results_summary_and_resume(tmp_path, primitive_synthesis, capsys):
    folder, out = _objects(tmp_path / "objects"), tmp_path / "out"
    job, robot, meshes, where = prepare_synthesize(_settings(folder, out), tmp_path / "run")
    assert [m.name for m in meshes] == ["ball.obj", "box.stl", "broken.stl"] and where == out
    rows = synthesize_objects(job, robot, meshes, where)
    assert [r["object"] for r in rows] == ["ball.obj", "box.stl", "broken.stl"]
    _check_results(out, physics=False)
    box = json.loads((out / "box.json").read_text())
    assert box["object"]["scale"] == 1.0 and box["settings"]["candidates"] == 16
    np.testing.assert_allclose(box["object"]["pose"][:3], np.subtract(OBJECT_CENTRE, 0.03), atol=1e-9)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary file left
    view = load_view(out / "box.json")  # one object's grasps in the viewer: its robot, mesh and contacts
    assert view.robot.name == "hand" and len(view.cones) == len(box["grasps"]) and view.problem.object.kind == "mesh"
    # a second run: every object skipped, no result file rewritten, the same summary
    files = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.glob("*.json")}
    summary = (out / "summary.csv").read_text()
    capsys.readouterr()
    again = synthesize_objects(job, robot, meshes, where)
    text = capsys.readouterr().out
    assert text.count("skipped") == 3
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.glob("*.json")} == files
    assert (out / "summary.csv").read_text() == summary and again == rows


def test_bad_settings_are_refused_before_any_work(tmp_path):
    folder = _objects(tmp_path / "objects")
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.txt").write_text("no meshes")
    cases = [({"objects": str(tmp_path / "missing")}, "no such folder or file"),
             ({"objects": str(empty)}, "no mesh files in the folder"),
             ({"objects": str(empty / "readme.txt")}, "not a mesh file"),
             ({"objects": None}, "objects= is required"),
             ({"fingers": ["thumb", "toe"]}, r"unknown finger\(s\) toe"),
             ({"fingers": ["thumb"]}, "2 or more different fingers"),
             ({"grasps": 0}, "grasps=0"),
             ({"verify": "mujoco"}, "verify"),
             ({"start": "warm"}, "start"),
             ({"power": "maybe"}, r"power='maybe': expected true or false"),
             ({"scale": -1.0}, "scale=-1"),
             ({"out": str(folder / "box.stl")}, "not a folder"),
             ({"robot": "arm_hand"}, r"centre=\[x,y,z\] is required for robot arm_hand \(a hand on an arm\)"),
             ({"robot": "arm_hand", "centre": [0.4, 0.0]}, "centre"),
             ({"robot": "manus"}, r"centre=\[x,y,z\] is required for robot manus"),
             ({"robot": "manus", "verify": "physics"}, r"robot manus's jaws do not move")]
    for change, message in cases:
        with pytest.raises(ConfigError, match=message):
            prepare_synthesize({**_settings(folder, tmp_path / "out"), **change}, tmp_path / "run")
    own = tmp_path / "own" / "own_hand.yaml"  # a hand with no FCNN trained: the search needs one, sampled starts not
    own.parent.mkdir()
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    own.write_text(yaml.safe_dump({**data, "name": "own_hand", "urdf": str(repo_root() / "urdf/hand/hand.urdf")}))
    settings = {**_settings(folder, tmp_path / "out"), "robot": str(own)}
    with pytest.raises(CheckpointError, match=r"own_hand\.fcnn\.pt: FCNN checkpoint not found; train one"):
        prepare_synthesize({**settings, "start": "random"}, tmp_path / "run")
    job = prepare_synthesize(settings, tmp_path / "run")[0]
    assert job.fingers == ["thumb", "index", "middle"]  # the default: found from the hand's kinematics
    (folder / "box.obj").write_text("")
    with pytest.raises(ConfigError, match=r"would both write box\.json"):
        prepare_synthesize(_settings(folder, tmp_path / "out"), tmp_path / "run")
    assert not (tmp_path / "out").exists() and not (tmp_path / "run").exists()
    assert SynthesizeGraspsJobCfg().fingers is None  # found from the hand: the shipped one's above


def test_script_refuses_a_missing_folder_with_exit_2(tmp_path):
    """A fresh process: the script's own entry point, one line, exit 2, nothing written."""
    res = subprocess.run([sys.executable, str(repo_root() / "scripts" / "synthesize_grasps.py"),
                          f"objects={tmp_path / 'missing'}", f"hydra.run.dir={tmp_path / 'run'}"],
                         capture_output=True, text=True, cwd=repo_root(), timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: objects=") and "no such folder or file" in lines[0]
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_with_physics(tmp_path, primitive_synthesis):
    """Each kept grasp checked in MuJoCo: its holds of 6 in the result and the summary."""
    folder, out = _objects(tmp_path / "objects"), tmp_path / "out"
    (folder / "ball.obj").unlink()
    synthesize_objects(*prepare_synthesize(_settings(folder, out, verify="physics"), tmp_path / "run"))
    rows = _check_results(out, physics=True, names=("box.stl", "broken.stl"))
    assert rows["box.stl"]["best_holds"] != ""


def test_an_object_too_large_for_the_hand_is_answered_with_why(tmp_path):
    """A 1 m box (its distance grid coarsened to fit, not 333 million points): no grasp, and the
    reason says no palm pose put every pad on it; the summary and its result file say so."""
    folder = tmp_path / "objects"
    folder.mkdir()
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(folder / "huge.stl")
    out = tmp_path / "out"
    job, robot, meshes, where = prepare_synthesize(_settings(folder, out, candidates=4), tmp_path / "run")
    (row,) = synthesize_objects(job, robot, meshes, where)
    data = json.loads((out / "huge.json").read_text())
    assert not data["grasps"] and row["grasps"] == 0
    assert "none put every chosen finger's pad on the object's surface" in data["reason"] == row["reason"]
    assert data["stats"]["tried"] == 200 and data["stats"]["touching"] == 0


def test_a_hand_on_an_arm_grasps_each_object_where_it_is_put(tmp_path):
    """robot=arm_hand with centre=: the object placed there, the arm reaching it, the grasp's arm
    joints in the result."""
    folder = tmp_path / "objects"
    folder.mkdir()
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(folder / "box.stl")
    out = tmp_path / "out"
    centre = [0.4, -0.15, -0.25]
    settings = _settings(folder, out, robot="arm_hand", centre=centre, candidates=8, grasps=1)
    (row,) = synthesize_objects(*prepare_synthesize(settings, tmp_path / "run"))
    data = json.loads((out / "box.json").read_text())
    np.testing.assert_allclose(data["object"]["pose"][:3], centre, atol=1e-9)  # a box's bounding box centre: its origin
    assert row["grasps"] == 1 and data["robot"] == "arm_hand"
    assert data["grasps"][0]["success"] and len(data["grasps"][0]["arm_joints"]) == 7


def test_each_objects_grasps_side_by_side_and_a_failed_picture_is_a_warning(tmp_path, monkeypatch, capsys):
    """pictures=true: <stem>.png beside <stem>.json, one panel per grasp; where drawing fails, the
    result stands and one warning says so."""
    from PIL import Image

    folder = tmp_path / "objects"
    folder.mkdir()
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(folder / "box.stl")
    out = tmp_path / "out"
    settings = _settings(folder, out, robot="arm_hand", centre=[0.4, -0.15, -0.25], candidates=8, pictures=True)
    (row,) = synthesize_objects(*prepare_synthesize(settings, tmp_path / "run"))
    assert row["grasps"] == 2
    with Image.open(out / "box.png") as picture:
        assert picture.width > 1.5 * picture.height  # two panels side by side

    def broken(*args, **kwargs):
        raise RuntimeError("no display")

    monkeypatch.setattr(job_module, "render_grasps", broken)
    again = tmp_path / "again"
    synthesize_objects(*prepare_synthesize({**settings, "out": str(again)}, tmp_path / "run"))
    assert (again / "box.json").is_file() and not (again / "box.png").exists()
    assert "warning: picture not written: RuntimeError: no display" in capsys.readouterr().err
