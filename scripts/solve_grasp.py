"""Solve a grasp: every joint of the robot so that each fingertip lands on its contact.

    python scripts/solve_grasp.py task=glass3 trials=20 seed=0
    python scripts/solve_grasp.py problem=my_problem.yaml out=result.json noise.sigma=0.1
    tensorboard --logdir outputs/solve_grasp

Exit status: 0 when it ran (solved or not: the result says which), 2 when the input was refused
(one line on stderr, no result file written), 1 for anything else.
"""

from __future__ import annotations

import sys

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from graspnet_torch.jobs.cli import check_group_overrides, user_errors_exit_2
from graspnet_torch.jobs.solve_grasp import solve_grasp


@hydra.main(config_path="../configs", config_name="solve_grasp", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    torch.set_num_threads(cfg.threads)
    solve_grasp(OmegaConf.to_container(cfg, resolve=True), HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    check_group_overrides(sys.argv[1:], ("task", "robot", "noise", "srv", "reward", "solver"))
    main()
