"""The synthesis experiment: its objects, its settings refused with one line, and its numbers
against an independent recomputation from the grasps it returns."""

from __future__ import annotations

import math

import numpy as np
import pytest

import graspnet_torch as gt
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.errors import ConfigError
from graspnet_torch.experiments import EXPERIMENTS, SynthesisExperimentCfg, run_synthesis, synthesis
from graspnet_torch.experiments.report import quick_settings
from graspnet_torch.experiments.synthesis import EXCLUDED, fresh_objects, pick_objects, summarize
from graspnet_torch.jobs.reproduce import shipped_experiments
from graspnet_torch.robot.shape import Shape
from graspnet_torch.solver.postures import trial_posture


def test_registered_and_quick_is_smaller():
    assert EXPERIMENTS["synthesis"].run is run_synthesis
    full = quick_settings(SynthesisExperimentCfg, shipped_experiments()["synthesis"], False)
    quick = quick_settings(SynthesisExperimentCfg, shipped_experiments()["synthesis"], True)
    assert full == SynthesisExperimentCfg() and full.objects >= 100 and full.robots == ("hand", "trifinger", "arm_hand")
    assert full.baseline == ("hand",)  # experiments/synthesis.py NO_BASELINE
    assert quick.robots == full.robots and quick.objects < full.objects and quick.candidates < full.candidates


def test_objects_drawn_by_seed_from_the_unused_ones():
    picked = [name for name, _ in pick_objects(100, 2026)]
    assert len(set(picked)) == 100 and picked == [name for name, _ in pick_objects(100, 2026)]
    assert not {f"blob{k:03d}" for k in EXCLUDED} & set(picked)
    assert picked != [name for name, _ in pick_objects(100, 2027)]
    _, shape = pick_objects(1, 3)[0]
    lo, hi = shape.trimesh().bounds  # placed as the synthesis job places an object: its box centred at 0.2 m
    assert shape.kind == "mesh" and shape.scale == 0.015 and np.allclose((lo + hi) / 2, [0, 0, 0.2], atol=1e-9)
    assert 0.02 < max(shape.trimesh().extents) < 0.2  # hand-sized in metres


def test_fresh_objects_are_none_the_experiment_tuning_or_tests_use():
    used = {int(name[4:]) for name, _ in pick_objects(100, 2026)} | set(EXCLUDED)
    fresh = fresh_objects(50, 7)
    assert len(set(fresh)) == 50 and not set(fresh) & used and fresh == fresh_objects(50, 7)
    assert fresh != fresh_objects(50, 8)


@pytest.mark.parametrize(("data", "key"), [({"objects": 0}, "objects"), ({"robots": ["nope"]}, "robots"),
                                           ({"candidates": 0}, "candidates"), ({"seed": -1}, "seed"),
                                           ({"baseline": "yes"}, "baseline"), ({"baseline": ["nope"]}, "baseline"),
                                           ({"jobs": 0}, "jobs"),
                                           ({"start": "warm"}, "start")])
def test_a_bad_setting_is_refused_with_one_line(data, key):
    with pytest.raises(ConfigError, match=rf"experiments\.synthesis\.{key}") as err:
        quick_settings(SynthesisExperimentCfg, data, False, "experiments.synthesis")
    assert "\n" not in str(err.value)


def test_summary_of_rows_by_hand():
    rows = [{"holds": [6, 3], "epsilon": [0.1, 0.2], "wall": 2.0, "first_s": 1.0, "depth_mm": [0.1, 0.4],
             "stats": {"physics_s": 1.0, "held": 1, "held_physics_s": 0.5}},
            {"holds": [2, 6, 6], "epsilon": [0.3], "wall": 3.0, "first_s": 2.5, "depth_mm": [0.0],
             "stats": {"physics_s": 1.5, "held": 2, "held_physics_s": 1.0}},
            {"holds": [], "epsilon": [], "wall": 5.0, "first_s": math.inf, "depth_mm": [], "stats": {"physics_s": 2.5}}]
    s = summarize(rows)
    assert s["top-1 holds %"] == pytest.approx(100 / 3) and s["any holds %"] == pytest.approx(200 / 3)
    assert s["median best epsilon"] == pytest.approx(0.25) and s["deepest mm"] == pytest.approx(0.4)
    assert s["verified"] == 3 and s["verified per s"] == pytest.approx(0.3) and s["median first s"] == 2.5
    # half the busy time in physics: 3 verified over half of the 10 s wall
    assert s["physics %"] == pytest.approx(50) and s["physics-bound per s"] == pytest.approx(0.6)
    assert summarize(rows, wall=5.0)["physics-bound per s"] == pytest.approx(1.2)  # two processes
    # every check one that holds: the 3 holding checks over their 1.5 s of the 10 s busy time
    assert s["holding-bound per s"] == pytest.approx(2.0)
    assert summarize(rows, wall=5.0)["holding-bound per s"] == pytest.approx(4.0)


@pytest.mark.slow
def test_quick_protocol_on_one_object_agrees_with_a_recomputation(tmp_path, monkeypatch):
    """The quick protocol's code path on a 6 cm cube in place of the random meshes (whose surface
    queries take minutes per object): every number against the returned grasps, checked again."""
    cube = Shape("box", (0.06, 0.06, 0.06), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    monkeypatch.setattr(synthesis, "pick_objects", lambda n, seed: [("cube", cube)][:n])
    cfg = SynthesisExperimentCfg(objects=1, seed=3, candidates=8, grasps=2, robots=("hand",), jobs=1)
    report = run_synthesis(cfg, tmp_path)
    assert (tmp_path / "synthesis_grasps.png").stat().st_size > 0
    robot = gt.load_robot("hand")
    for method in ("synthesis", "baseline"):
        rows = report.results["hand", method]
        assert len(rows) == 1
        grasps = rows[0]["grasps"]
        assert len(grasps) <= 2 and all(g.physics is not None for g in grasps)
        top1 = np.mean([bool(r["grasps"]) and r["grasps"][0].holds == 6 for r in rows]) * 100
        anyk = np.mean([any(g.holds == 6 for g in r["grasps"]) for r in rows]) * 100
        assert report.numbers[f"hand/{method}/top-1 holds %"] == pytest.approx(top1)
        assert report.numbers[f"hand/{method}/any holds %"] == pytest.approx(anyk)
        assert report.numbers[f"hand/{method}/verified"] == sum(g.holds == 6 for r in rows for g in r["grasps"])
        deepest = 0.0
        for g in grasps:  # FCL and the physics check again, independently of the run
            scene = CollisionScene(robot, g.problem, object_tolerance=0.0, touching=False)
            deepest = max(deepest, *scene.check(trial_posture(robot, g.result.best)).object_links.values(), 0.0)
            assert sum(gt.simulate_grasp(g.problem, g.result, robot=robot).directions.values()) == g.holds
        assert report.numbers[f"hand/{method}/deepest mm"] == pytest.approx(deepest * 1000)
    synthesized = report.results["hand", "synthesis"][0]["grasps"]
    if synthesized:
        assert report.numbers["hand/synthesis/median best epsilon"] == pytest.approx(
            max(g.quality.epsilon for g in synthesized))
    assert any("deep" in what for what, _ in report.checks) and "| hand | baseline |" in report.body


@pytest.mark.slow
def test_processes_over_the_objects_give_the_same_grasps(tmp_path, monkeypatch):
    """jobs=2 (joblib processes over the objects) reports what one process does: each object is
    synthesized with its own seed."""
    cube = Shape("box", (0.06, 0.06, 0.06), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    sphere = Shape("sphere", (0.035,), np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
    monkeypatch.setattr(synthesis, "pick_objects", lambda n, seed: [("cube", cube), ("sphere", sphere)][:n])
    numbers = []
    for jobs in (1, 2):
        cfg = SynthesisExperimentCfg(objects=2, seed=3, candidates=6, grasps=2, robots=("hand",), baseline=(),
                                     jobs=jobs)
        report = run_synthesis(cfg, tmp_path / str(jobs))
        rows = report.results["hand", "synthesis"]
        numbers.append([(r["holds"], r["epsilon"]) for r in rows])
    assert numbers[0] == numbers[1] and any(h for h, _ in numbers[0])
