"""A hand by config from an object: TriFinger (examples/trifinger) grasping one of pybullet's random
objects that tuned its pads and squeeze (626: excluded from the synthesis experiment), each grasp
checked again by FCL, the surface fields and MuJoCo; its config's pads against the derived ones."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.paths import repo_root
from graspnet_torch.quality import grasp_quality
from graspnet_torch.solver.contact import surface_fields
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.candidates import iter_contact_sets
from graspnet_torch.tasks.objects import centred_mesh

TRIFINGER = repo_root() / "examples" / "trifinger" / "trifinger.yaml"
FINGERS = ("f0", "f120", "f240")
pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    importlib.util.find_spec("robot_properties_fingers") is None or importlib.util.find_spec("mujoco") is None,
    reason="TriFinger needs the 'robot_properties_fingers' package and the check MuJoCo (the dev extra)")]


@pytest.fixture(scope="module")
def blob():
    import pybullet_data

    return centred_mesh(Path(pybullet_data.getDataPath()) / "random_urdfs" / "626" / "626.obj", 0.015)


def test_trifinger_grasps_an_object_that_holds_and_checks_again(blob):
    robot = gt.load_robot(TRIFINGER)
    stats: dict = {}
    grasps = gt.synthesize_grasps(robot, blob, n_grasps=1, fingers=FINGERS, candidates=16, seed=0,
                                  physics=lambda p, r, robot: gt.simulate_grasp(p, r, robot=robot), stats=stats)
    held = [g for g in grasps if g.holds == 6]
    assert held and stats["held"] >= 1
    assert 0 < stats["held_physics_s"] <= stats["physics_s"]  # the holding checks' part of the physics time
    for g in held:
        posture = trial_posture(robot, g.result.best)
        fields = surface_fields(robot, g.problem, [posture])[0]
        assert max(fields["pad_distance_mm"].values()) < 1.0
        assert max(fields["normal_angle_deg"].values()) <= 60.0 + 1e-6  # the config's cone
        depth = CollisionScene(robot, g.problem, object_tolerance=0.0, touching=False).check(posture).object_links
        assert max(depth.values(), default=0.0) <= 1e-3
        assert gt.simulate_grasp(g.problem, g.result, robot=robot).holds == 6


def test_the_config_pads_give_more_force_closure_sets_than_the_derived_ones(blob, tmp_path):
    """The same palm poses with the pads the URDF gives (the side each finger curls toward, its
    last joint decreasing: more than 60 degrees off the holder's axis where the tips close) and
    with the config's (facing the axis): both give force-closure sets, the config's more. (Taken
    as the side the last joint's positive sense moves, the derived pads gave fewer than a fifth of
    the config's here.)"""
    data = yaml.safe_load(TRIFINGER.read_text())
    for finger in data["fingers"].values():
        finger.pop("pad")
    (tmp_path / "derived.yaml").write_text(yaml.safe_dump(data))
    closure = {}
    for name, robot in (("config", gt.load_robot(TRIFINGER)), ("derived", gt.load_robot(tmp_path / "derived.yaml"))):
        sets = [s for batch in iter_contact_sets(robot, blob, FINGERS, 0, cone_deg=60.0, max_tries=320) for s in batch]
        centre = np.asarray(blob.pose[:3])
        closure[name] = sum(bool(grasp_quality(s.contacts, s.normals, centre, 0.6).force_closure) for s in sets)
    assert closure["derived"] >= 5 and closure["config"] > closure["derived"], closure
