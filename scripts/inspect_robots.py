"""Print a table of the shipped robots and write a PNG of each at its home posture.

    python scripts/inspect_robots.py
    python scripts/inspect_robots.py robots=[hand] out_dir=outputs/robots
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import InspectRobotsJobCfg
from graspnet_torch.jobs.inspect_robots import inspect_robots, prepare_inspect


@hydra.main(config_path="../configs", config_name="inspect_robots", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    inspect_robots(*prepare_inspect(container(cfg), HydraConfig.get().runtime.output_dir))


if __name__ == "__main__":
    run_cli(main, InspectRobotsJobCfg, config_name="inspect_robots", prepare=prepare_inspect)
