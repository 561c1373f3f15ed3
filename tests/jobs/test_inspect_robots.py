"""The foundation's main job: robot table + pictures; and the script's exit codes."""

from __future__ import annotations

import subprocess
import sys

from graspnet_torch.jobs.inspect_robots import inspect_robots
from graspnet_torch.paths import repo_root


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


def _script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(repo_root() / "scripts" / "inspect_robots.py"), *args],
                          capture_output=True, text=True, cwd=repo_root())


def test_script_unknown_robot_exits_2_with_one_line(tmp_path):
    res = _script("robots=[robonaut]", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown robot 'robonaut'" in lines[0]
    assert not list(tmp_path.glob("*.png"))


def test_script_runs(tmp_path):
    res = _script("robots=[arm_hand]", f"hydra.run.dir={tmp_path}")
    assert res.returncode == 0, res.stderr
    assert "arm_hand" in res.stdout and (tmp_path / "arm_hand.png").is_file()
