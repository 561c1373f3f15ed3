"""A robot's solver_defaults: stored as written by the robot, checked against the groups' settings
by the solver (solver/defaults.py) and refused by the solve job before any work."""

from __future__ import annotations

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.jobs.configs import SolveGraspJobCfg
from graspnet_torch.jobs.solve_grasp import with_robot_defaults
from graspnet_torch.paths import configs_dir
from graspnet_torch.robot import available_robots, load_robot_cfg
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
    return load_robot_cfg(path)


@pytest.mark.parametrize(("defaults", "message"), BAD)
def test_bad_solver_defaults_are_refused_naming_the_robots_file(tmp_path, defaults, message):
    cfg = _hand_cfg(tmp_path, defaults)
    assert cfg.solver_defaults == defaults  # the robot keeps them as written
    with pytest.raises(gt.ConfigError, match=r"robot.yaml: " + message):
        check_solver_defaults(cfg)
    with pytest.raises(gt.ConfigError, match=r"robot.yaml: " + message):
        with_robot_defaults(SolveGraspJobCfg(), {}, cfg)


def test_the_shipped_solver_defaults_pass():
    for name in available_robots():
        check_solver_defaults(load_robot_cfg(name))


def test_the_command_lines_solver_group_leaves_the_cone_and_squeeze_to_the_robot(tmp_path):
    """configs/solver/srv.yaml writes normal_cone_deg and squeeze_mm as null: the robot's
    solver_defaults where it sets them, else the settings' defaults; a value given wins."""
    from graspnet_torch.jobs.solve_grasp import job_settings
    from graspnet_torch.solver.config import SolverCfg

    group = yaml.safe_load((configs_dir() / "solver" / "srv.yaml").read_text())
    assert group["normal_cone_deg"] is None and group["squeeze_mm"] is None
    robot = _hand_cfg(tmp_path, {"solver": {"normal_cone_deg": 60, "squeeze_mm": 15}})
    plain = load_robot_cfg("hand")
    for given, cfg, want in (({}, robot, (60, 15)), ({}, plain, (SolverCfg.normal_cone_deg, SolverCfg.squeeze_mm)),
                             ({"normal_cone_deg": 45}, robot, (45, 15))):
        job, groups, _ = job_settings({"solver": {**group, **given}})
        _, solver = with_robot_defaults(job, groups, cfg)
        assert (solver.normal_cone_deg, solver.squeeze_mm) == want
