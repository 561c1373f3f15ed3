"""Solve a grasp: every joint of the robot so that each fingertip lands on its contact.

    python scripts/solve_grasp.py task=glass3 trials=20 seed=0
    python scripts/solve_grasp.py problem=my_problem.yaml out=result.json noise.sigma=0.1
    python scripts/solve_grasp.py problem=problems/ out=results/     # many: one result each (or a .jsonl file)
    tensorboard --logdir outputs/solve_grasp

Exit status: 0 when it ran (solved or not: the result says which), 2 when the input was refused
(one line on stderr, no result file written), 1 for anything else.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import SolveGraspJobCfg
from graspnet_torch.jobs.solve_many import prepare_job, run_job


@hydra.main(config_path="../configs", config_name="solve_grasp", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    hydra_cfg = HydraConfig.get()
    run_job(container(cfg), hydra_cfg.runtime.output_dir, list(hydra_cfg.overrides.task))


if __name__ == "__main__":
    run_cli(main, SolveGraspJobCfg, config_name="solve_grasp", prepare=prepare_job)
