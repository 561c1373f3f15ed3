"""Print a table of the shipped robots and write a PNG of each at its home posture.

    python scripts/inspect_robots.py
    python scripts/inspect_robots.py robots=[hand] out_dir=outputs/robots
"""

from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import check_group_overrides, user_errors_exit_2
from graspnet_torch.jobs.inspect_robots import inspect_robots


@hydra.main(config_path="../configs", config_name="inspect_robots", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    inspect_robots(list(cfg.robots), cfg.out_dir)


if __name__ == "__main__":
    check_group_overrides(sys.argv[1:], ("robot", "fcnn"))
    main()
