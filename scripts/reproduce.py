"""Reproduce the paper: every experiment, one report (REPRODUCTION.md beside its figures).

    python scripts/reproduce.py out=reports                  # make reproduce (~30 min on 2 cores)
    python scripts/reproduce.py quick=true                   # make reproduce-quick: the reduced protocol
    python scripts/reproduce.py +experiment=table3           # one experiment (configs/experiment/)
    python scripts/reproduce.py +experiment=table3 experiments.table3.runs=10
    python scripts/reproduce.py -m +experiment=fig3 experiments.fig3.a=1,20 hydra/launcher=joblib

Exit status: 0 when every experiment ran and the report holds every table and figure, 2 when the
settings were refused (one line on stderr, nothing written), 1 for anything else.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.reproduce import ReproduceJobCfg, prepare_reproduce, reproduce


@hydra.main(config_path="../configs", config_name="reproduce", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    hydra_cfg = HydraConfig.get()
    reproduce(prepare_reproduce(container(cfg), hydra_cfg.runtime.output_dir), list(hydra_cfg.overrides.task))


if __name__ == "__main__":
    run_cli(main, ReproduceJobCfg, config_name="reproduce", prepare=prepare_reproduce)
