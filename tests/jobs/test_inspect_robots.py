"""The foundation's main job: robot table + pictures; and the script's exit codes."""

from __future__ import annotations

import pytest

from graspnet_torch.jobs.inspect_robots import inspect_robots
from tests.in_process import ScriptRun, run_script


@pytest.mark.slow
def test_inspect_robots_writes_pictures_and_table(tmp_path, capsys):
    rows = inspect_robots(["hand", "manus"], tmp_path)
    out = capsys.readouterr().out
    assert [r["robot"] for r in rows] == ["hand", "manus"]
    assert rows[0]["DOF"] == 26 and rows[1]["DOF"] == 9
    for name in ("hand", "manus"):
        png = tmp_path / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
        assert name in out
    assert rows[0]["thumb-index gap (mm)"] < 0.1
    assert not list(tmp_path.glob("*.tmp*")) and not list(tmp_path.glob("tmp*"))


def _script(*args: str) -> ScriptRun:
    """scripts/inspect_robots.py's entry point, in this process (:func:`run_script`)."""
    return run_script("inspect_robots.py", *args)


def test_script_unknown_robot_exits_2_with_one_line(tmp_path):
    res = _script("robots=[robonaut]", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown robot 'robonaut'" in lines[0]
    assert not list(tmp_path.glob("*.png"))


@pytest.mark.slow
def test_script_runs(tmp_path):
    """A shipped robot and one given by its YAML path, in one list."""
    from tests.mesh_robots import bare_hand_urdf, write_robot

    bare = write_robot(tmp_path / "bare", bare_hand_urdf(), name="barehand")
    res = _script(f"robots=[arm_hand,{bare}]", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    assert "arm_hand" in res.stdout and (tmp_path / "arm_hand.png").is_file()
    assert "barehand" in res.stdout and (tmp_path / "barehand.png").is_file()


@pytest.mark.slow
def test_robots_by_path_get_generic_opposition_panels(tmp_path, capsys):
    """A hand given by its YAML path (mesh palm; no finger called thumb: the first finger opposes
    the others) and one without any geometry: table rows, gaps and pictures."""
    from tests.mesh_robots import bare_hand_urdf, mesh_hand_urdf, write_box_mesh, write_robot

    write_box_mesh(tmp_path / "meshhand" / "meshes" / "palm.stl")
    urdf = mesh_hand_urdf('<mesh filename="package://meshhand/meshes/palm.stl"/>').replace("thumb", "first")
    mesh = write_robot(tmp_path / "meshhand", urdf)
    text = mesh.read_text().replace("thumb", "first")
    mesh.write_text(text)
    bare = write_robot(tmp_path / "bare", bare_hand_urdf(), name="barehand")
    rows = inspect_robots([str(mesh), str(bare)], tmp_path / "out")
    assert [r["robot"] for r in rows] == ["meshhand", "barehand"]
    assert rows[0]["first-index gap (mm)"] < 0.01 and rows[1]["thumb-index gap (mm)"] < 0.01
    for name in ("meshhand", "barehand"):
        assert (tmp_path / "out" / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_a_picture_failure_is_a_warning_per_robot(tmp_path, capsys, monkeypatch):
    import graspnet_torch.jobs.inspect_robots as job

    def broken(robot, *args, **kwargs):
        raise RuntimeError(f"no picture of {robot.name}\nsecond line")

    monkeypatch.setattr(job, "render_robot", broken)
    rows = inspect_robots(["manus"], tmp_path)
    assert rows[0]["picture"] == "-"
    assert capsys.readouterr().err.strip().splitlines() == [
        "warning: manus: picture not written: RuntimeError: no picture of manus second line"]


def test_opposition_keeps_padded_and_fixed_slots(hand):
    """Slots whose limits are equal do not move; the other fingers keep their start."""
    from graspnet_torch.jobs.inspect_robots import opposing_fingers, opposition_posture

    assert opposing_fingers(hand) == [("thumb", "index"), ("thumb", "middle")]
    home = hand.home_posture()
    posture, gap = opposition_posture(hand, "thumb", "ring", home)
    assert gap < 1e-4
    moved = (posture.fingers != home.fingers).any(dim=1).tolist()
    assert moved == [True, False, False, True, False]

