"""Robot pictures never fail because of a robot's geometry: meshes are drawn (decimated), a robot
without geometry is a skeleton, a mesh that cannot be loaded is a warning (and a skeleton), and a
solve whose pictures fail still writes its result."""

from __future__ import annotations

import json

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import repo_root
from graspnet_torch.viz import Panel, render_robot
from graspnet_torch.viz import robot as viz_robot
from tests.mesh_robots import bare_hand_urdf, mesh_hand_urdf, write_box_mesh, write_robot

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def skeletons(monkeypatch):
    """Counts the skeletons drawn."""
    calls = []
    real = viz_robot.draw_skeleton

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(viz_robot, "draw_skeleton", counting)
    return calls


def _draw(robot, path):
    home = robot.home_posture()
    return render_robot(robot, [Panel("home", home), Panel("side", home, (15.0, -15.0))], path)


@pytest.mark.slow
def test_a_mesh_robot_is_drawn(tmp_path, capsys, skeletons):
    write_box_mesh(tmp_path / "meshes" / "palm.stl", subdivisions=5)  # 20480 faces: decimated
    robot = gt.load_robot(write_robot(tmp_path, mesh_hand_urdf('<mesh filename="meshes/palm.stl"/>')))
    shapes, errors = viz_robot.drawable_shapes(robot)
    assert "mesh" in {s.kind for s in shapes} and not errors
    path = _draw(robot, tmp_path / "mesh.png")
    assert path.read_bytes()[:8] == PNG and path.stat().st_size > 10_000
    assert not skeletons and capsys.readouterr().err == ""


@pytest.mark.slow
def test_a_robot_without_geometry_is_a_skeleton(tmp_path, capsys, skeletons):
    robot = gt.load_robot(write_robot(tmp_path, bare_hand_urdf(), name="barehand"))
    path = _draw(robot, tmp_path / "bare.png")
    assert path.read_bytes()[:8] == PNG
    assert len(skeletons) == 2 and capsys.readouterr().err == ""  # one per panel, no warning


def test_a_visual_only_robot_draws_its_visual_meshes(tmp_path, skeletons):
    write_box_mesh(tmp_path / "palm.obj")
    urdf = bare_hand_urdf("visualhand").replace('<link name="palm">', '<link name="palm"><visual><geometry>'
                                                '<mesh filename="palm.obj"/></geometry></visual>')
    robot = gt.load_robot(write_robot(tmp_path, urdf, name="visualhand"))
    shapes, errors = viz_robot.drawable_shapes(robot)
    assert [s.kind for s in shapes] == ["mesh"] and not errors
    assert _draw(robot, tmp_path / "v.png").read_bytes()[:8] == PNG and not skeletons


@pytest.mark.slow
def test_a_broken_mesh_is_one_warning_and_a_skeleton(tmp_path, capsys, skeletons):
    robot = gt.load_robot(write_robot(tmp_path, mesh_hand_urdf('<mesh filename="package://gone/palm.stl"/>')))
    path = _draw(robot, tmp_path / "broken.png")
    assert path.read_bytes()[:8] == PNG and len(skeletons) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: meshhand.urdf: link 'palm' collision: mesh "
                                               "'package://gone/palm.stl' not found"), err


@pytest.mark.slow
def test_a_solve_with_an_unresolvable_mesh_writes_its_result_and_warns(tmp_path, capsys):
    """A hand (the shipped one's URDF and FCNN checkpoint) whose palm has an extra collision mesh
    that cannot be found: the solve (no object: no collision check) writes its result; the
    picture warns once and is drawn anyway."""
    from graspnet_torch.jobs import solve_grasp as job

    urdf = (repo_root() / "urdf" / "hand" / "hand.urdf").read_text()
    broken = '<collision><geometry><mesh filename="package://lost/meshes/palm.stl"/></geometry></collision>'
    assert urdf.count('<link name="palm">') == 1
    urdf = urdf.replace('<link name="palm">', '<link name="palm">' + broken)
    (tmp_path / "lost_hand.urdf").write_text(urdf)
    cfg = yaml.safe_load((repo_root() / "configs" / "robot" / "hand.yaml").read_text())
    cfg.update(name="lost_hand", urdf="lost_hand.urdf", checkpoint=str(repo_root() / "checkpoints/hand/fcnn.pt"))
    robot_yaml = tmp_path / "lost_hand.yaml"
    robot_yaml.write_text(yaml.safe_dump(cfg, sort_keys=False))
    glass = gt.GraspProblem.from_task("glass3")
    problem = tmp_path / "p.yaml"
    problem.write_text(yaml.safe_dump({"robot": str(robot_yaml), "contacts": [
        {"finger": f, "position": p.tolist()} for f, p in zip(glass.fingers, glass.contacts_world(), strict=True)]}))
    out = tmp_path / "r.json"
    job.solve_grasp({"problem": str(problem), "trials": 2, "max_iterations": 5, "out": str(out), "tensorboard": False,
                     "pictures": True, "threads": 1}, tmp_path / "run")
    assert json.loads(out.read_text())["robot"] == "lost_hand"
    assert (tmp_path / "run" / "posture.png").read_bytes()[:8] == PNG
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "package://lost/meshes/palm.stl' not found" in err[0], err
