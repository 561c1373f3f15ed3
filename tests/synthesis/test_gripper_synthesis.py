"""A gripper chooses its two points: antipodal pairs as wide as its jaws, solved by the search
among obstacles; checked by the URDF's link frames and by numpy, not by the code that chose them."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

import graspnet_torch as gt
from graspnet_torch.collision.surface import surface_distance, surface_normals
from graspnet_torch.jobs.solve_many import run_job
from graspnet_torch.jobs.synthesize import prepare_synthesize, synthesize_objects
from graspnet_torch.robot.shape import Shape
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.candidates import FRICTION
from graspnet_torch.synthesis.pairs import WIDTH_TOL_M, antipodal_pairs, jaw_width
from graspnet_torch.synthesis.synthesize import no_grasp_reason
from graspnet_torch.viz.viewer import load_view

TABLE = Shape("box", (0.6, 1.2, 0.72), np.array([1.15, 0.2, 0.36, 0.0, 0.0, 0.0]))  # task cube's
CUBE = Shape("box", (0.07, 0.07, 0.07), np.array([0.95, 0.2, 0.755, 0.0, 0.0, 0.0]))


@pytest.fixture(scope="module")
def manus() -> gt.Robot:
    return gt.load_robot("manus")


def test_jaw_width_is_the_marked_points_distance(manus: gt.Robot) -> None:
    frames = manus.link_frames(manus.home_posture())
    a, b = (frames[name][:3, 3] for name in manus.cfg.gripper_points)
    assert jaw_width(manus) == pytest.approx(np.linalg.norm(a - b), abs=1e-12)


def test_antipodal_pairs_on_a_bar_span_its_matching_width_only() -> None:
    """A 70 x 50 x 40 mm bar: the only 70 mm antipodal pairs cross it along x; each point on the
    surface, the pair 70 mm apart, its line along both inward normals (within the friction cone)."""
    bar = Shape("box", (0.07, 0.05, 0.04), np.array([0.1, -0.2, 0.3, 0.0, 0.0, 0.5]))
    pairs = antipodal_pairs(bar, 0.07, 8, seed=1)
    assert len(pairs) == 8
    axis = np.array([math.cos(0.5), math.sin(0.5), 0.0])  # the bar's x axis in the world (turned 0.5 rad about z)
    cone = math.degrees(math.atan(FRICTION))
    for pair in pairs:
        np.testing.assert_allclose(surface_distance(bar, pair.points), 0.0, atol=1e-9)
        line = pair.points[1] - pair.points[0]
        assert abs(np.linalg.norm(line) - 0.07) <= WIDTH_TOL_M
        assert abs(line @ axis) / np.linalg.norm(line) > 0.999
        inward = -surface_normals(bar, pair.points)
        u = line / np.linalg.norm(line)
        angles = np.degrees(np.arccos(np.clip([inward[0] @ u, -inward[1] @ u], -1.0, 1.0)))
        assert angles.max() <= cone
        np.testing.assert_allclose(pair.normals, inward, atol=1e-9)
    mids = np.array([p.points.mean(axis=0) for p in pairs])
    off = np.linalg.norm(mids - bar.pose[:3], axis=1)
    assert off[0] <= off.max() and off[0] < 0.01  # the best pair passes near the centre
    assert antipodal_pairs(Shape("sphere", (0.05,), np.zeros(6)), 0.07, 4) == []  # a 10 cm ball: none 70 mm wide


def test_manus_grasps_the_cube_on_the_table_at_its_chosen_points(manus: gt.Robot) -> None:
    stats: dict = {}
    grasps = gt.synthesize_grasps(manus, CUBE, n_grasps=2, candidates=16, seed=0, trials=8, obstacles=(TABLE,),
                                  stats=stats)
    assert grasps and stats["pairs"] == 16
    for g in grasps:
        assert g.success and g.result.best.collisions == 0
        frames = manus.link_frames(trial_posture(manus, g.result.best))
        marked = np.stack([frames[name][:3, 3] for name in manus.cfg.gripper_points])
        d = min(np.linalg.norm(m - g.contacts, axis=1).sum() for m in (marked, marked[::-1]))
        assert d < 1e-3  # eq. 26: the marked points on the chosen points (either pairing), by the URDF's frames
        assert g.to_dict()["points"] and g.to_dict()["fingers"] == list(manus.cfg.gripper_points)
    with pytest.raises(gt.ProblemError, match=r"its jaws do not move .* no squeeze to check in physics"):
        gt.synthesize_grasps(manus, CUBE, n_grasps=1, physics=gt.simulate_grasp)


def test_no_pair_as_wide_as_the_jaws_is_said(manus: gt.Robot) -> None:
    stats: dict = {}
    assert gt.synthesize_grasps(manus, Shape("sphere", (0.05,), CUBE.pose), n_grasps=1, stats=stats) == []
    assert no_grasp_reason(stats).startswith("no grasp found: no antipodal pair 70.0 mm apart")


def test_points_auto_problem_file(tmp_path) -> None:
    """``points: auto`` with the table: the result file lists the chosen points; no physics."""
    problem = tmp_path / "cube.yaml"
    problem.write_text("robot: manus\nobject: {shape: box, size: [0.07, 0.07, 0.07], "
                       "pose: [0.95, 0.2, 0.755, 0, 0, 0]}\npoints: auto\ngrasps: 1\nobstacles:\n"
                       "  - {shape: box, size: [0.6, 1.2, 0.72], pose: [1.15, 0.2, 0.36, 0, 0, 0]}\n")
    out = tmp_path / "result.json"
    run_job({"problem": str(problem), "out": str(out), "seed": 0}, tmp_path / "run")
    data = json.loads(out.read_text())
    assert data["success"] and data["physics_checked"] is False and len(data["points"]) == 2
    assert data["auto"] == {"fingers": [], "grasps": 1}
    with pytest.raises(gt.ProblemError, match=r"fingers: robot 'manus' grasps with its two marked points"):
        gt.GraspProblem.from_mapping({"robot": "manus", "object": CUBE.to_mapping(), "points": "auto",
                                      "fingers": 2}, "p.yaml")
    with pytest.raises(gt.ProblemError, match=r"points: auto: the solver needs points"):
        gt.solve(problem, trials=1)


def test_folder_job_and_viewer_for_the_gripper(tmp_path) -> None:
    """scripts/synthesize_grasps.py robot=manus centre=...: a 70 x 50 x 40 mm bar's result file, and
    the viewer shows its grasps with their two points."""
    folder = tmp_path / "objects"
    folder.mkdir()
    trimesh.creation.box(extents=(0.07, 0.05, 0.04)).export(folder / "bar.stl")
    out = tmp_path / "out"
    settings = {"objects": str(folder), "out": str(out), "robot": "manus", "centre": [0.95, 0.2, 0.8], "grasps": 1,
                "candidates": 8, "verify": "none", "progress": False}
    (row,) = synthesize_objects(*prepare_synthesize(settings, tmp_path / "run"))
    assert row["grasps"] == 1 and (out / "bar.png").is_file()  # its grasps side by side
    view = load_view(out / "bar.json")
    contacts, inward = view.cones[0]
    assert contacts.shape == (2, 3) and abs(np.linalg.norm(contacts[0] - contacts[1]) - 0.07) <= WIDTH_TOL_M
    np.testing.assert_allclose(inward[0], -inward[1], atol=1e-9)  # the bar's opposite faces
