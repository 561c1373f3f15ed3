"""graspnet_torch.meshes.sample_even: trimesh's even surface sample, the same points, without the
warning trimesh logs when it comes out short (a user's run shows no library warning)."""

from __future__ import annotations

import logging

import numpy as np
import trimesh

from graspnet_torch.meshes import sample_even
from graspnet_torch.paths import repo_root

SHORT = repo_root() / "examples" / "shadow_hand" / "meshes" / "collision" / "forearm_E3M5.obj"  # 3000 asked: fewer


def test_a_short_even_sample_is_trimeshs_own_and_logs_nothing(caplog):
    mesh = trimesh.load(SHORT, force="mesh")
    with caplog.at_level(logging.DEBUG, logger="trimesh"):
        expected, _ = trimesh.sample.sample_surface_even(mesh, 3000, seed=0)
    assert any("only got" in r.getMessage() for r in caplog.records)  # trimesh's own call warns here
    caplog.clear()
    with caplog.at_level(logging.DEBUG, logger="trimesh"):
        points = sample_even(mesh, 3000)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert points.dtype == np.float64 and len(points) < 3000
    np.testing.assert_array_equal(points, expected)
    assert logging.getLogger("trimesh.sample").level == logging.NOTSET  # the level restored
