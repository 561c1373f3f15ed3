"""Palm poses at the hand's own scale: the object's gap to the palm follows the fingertips' reach."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import repo_root
from graspnet_torch.synthesis.drafts import palm_front, palm_gap

SCALE = 1.5


def _scaled_hand(folder: Path, scale: float) -> Path:
    """The shipped hand's URDF and config with every length times ``scale`` (link origins, boxes,
    cylinders, spheres, the config's given pad point)."""
    cfg = yaml.safe_load((repo_root() / "configs/robot/hand.yaml").read_text(encoding="utf-8"))
    text = (repo_root() / cfg["urdf"]).read_text(encoding="utf-8")

    def times(match: re.Match) -> str:
        values = " ".join(repr(float(v) * scale) for v in match.group(2).split())
        return f'{match.group(1)}="{values}"'

    text = re.sub(r'\b(xyz|size|radius|length)="([^"]*)"', times, text)
    (folder / "hand.urdf").write_text(text, encoding="utf-8")
    cfg["urdf"] = "hand.urdf"
    pad = cfg["fingers"]["thumb"]["pad"]
    pad["point"] = [v * scale for v in pad["point"]]
    path = folder / "hand_scaled.yaml"
    path.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    return path


def _gap(robot: gt.Robot) -> tuple[float, float]:
    rows = [list(robot.fingers).index(f) for f in ("thumb", "index", "middle")]
    return palm_gap(robot, rows, palm_front(robot, rows))


def test_a_hand_half_again_as_large_draws_its_objects_half_again_as_far(tmp_path: Path) -> None:
    small = _gap(gt.load_robot("hand"))
    large = _gap(gt.load_robot(_scaled_hand(tmp_path, SCALE)))
    assert small[0] == large[0] == 0.0
    assert 0.02 < small[1] < 0.05  # a human-sized hand: a few centimetres
    assert large[1] == pytest.approx(SCALE * small[1], rel=1e-9)
