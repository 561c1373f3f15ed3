"""A robot's ``solver_defaults`` (its config's settings of the ``srv``, ``reward`` and ``solver``
groups) checked against those groups' settings: the robot stores them as written, the solver
knows what they mean."""

from __future__ import annotations

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.config import SOLVER_DEFAULT_GROUPS, RobotCfg
from graspnet_torch.settings import build
from graspnet_torch.solver.config import RewardCfg, SolverCfg
from graspnet_torch.srv.network import SRVNetCfg

__all__ = ["DEFAULT_GROUPS", "check_solver_defaults"]

DEFAULT_GROUPS = dict(zip(SOLVER_DEFAULT_GROUPS, (SRVNetCfg, RewardCfg, SolverCfg), strict=True))  # name -> settings


def check_solver_defaults(cfg: RobotCfg) -> None:
    """Refuse a robot whose ``solver_defaults`` hold a setting its group does not have or a value
    out of its range, in one line naming the robot's file: ``<file>: solver_defaults.srv.lr_bp=-1:
    expected ...``."""
    for group, values in cfg.solver_defaults.items():
        try:
            build(DEFAULT_GROUPS[group], dict(values), f"solver_defaults.{group}")
        except ConfigError as exc:
            raise ConfigError(f"{cfg.source}: {exc}") from None
