"""A robot's solver_defaults: stored as written by the robot, checked against the groups' settings
by the solver (solver/defaults.py) and refused by the solve job before any work."""

from __future__ import annotations

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.jobs.configs import SolveGraspJobCfg
from graspnet_torch.jobs.solve_grasp import with_robot_defaults
from graspnet_torch.paths import configs_dir
from graspnet_torch.solver.defaults import check_solver_defaults

BAD = [
    ({"srv": {"lr_bp": -1}}, r"solver_defaults.srv.lr_bp=-1: expected a number in \[0, 100\]"),
    ({"srv": {"learning": 0.1}}, r"unknown setting 'solver_defaults.srv.learning'"),
    ({"reward": {"kind": "r9"}}, r"solver_defaults.reward.kind='r9': expected one of r1, r2, r3, r4"),
]


def _hand_cfg(tmp_path, defaults):
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data["solver_defaults"] = defaults
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return gt.load_robot_cfg(path)


@pytest.mark.parametrize(("defaults", "message"), BAD)
def test_bad_solver_defaults_are_refused_naming_the_robots_file(tmp_path, defaults, message):
    cfg = _hand_cfg(tmp_path, defaults)
    assert cfg.solver_defaults == defaults  # the robot keeps them as written
    with pytest.raises(gt.ConfigError, match=r"robot.yaml: " + message):
        check_solver_defaults(cfg)
    with pytest.raises(gt.ConfigError, match=r"robot.yaml: " + message):
        with_robot_defaults(SolveGraspJobCfg(), {}, cfg)


def test_the_shipped_solver_defaults_pass():
    for name in gt.available_robots():
        check_solver_defaults(gt.load_robot_cfg(name))
