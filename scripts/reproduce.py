"""Reproduce the paper: every experiment, one report (REPRODUCTION.md beside its figures).

    python scripts/reproduce.py out=reports                  # make reproduce (~30 min on 2 cores)
    python scripts/reproduce.py quick=true                   # make reproduce-quick: the reduced protocol
    python scripts/reproduce.py +experiment=table3           # one experiment (configs/experiment/)
    python scripts/reproduce.py +experiment=table3 experiments.table3.runs=10
    python scripts/reproduce.py -m +experiment=fig3 experiments.fig3.a=1,20 hydra/launcher=joblib
    python scripts/reproduce.py +experiment=manus check=true  # exit 1 when a target is missed

Exit status: 0 when every experiment ran and the report holds every table and figure (and, with
``check=true``, every target of this project was met), 2 when the settings were refused (one line
on stderr, nothing written), 1 for anything else.
"""

from __future__ import annotations

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.errors import say
from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.reproduce import NUMBERS, ReproduceJobCfg, missed_targets, prepare_reproduce, reproduce


@hydra.main(config_path="../configs", config_name="reproduce", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    hydra_cfg = HydraConfig.get()
    plan = prepare_reproduce(container(cfg), hydra_cfg.runtime.output_dir)
    reproduce(plan, list(hydra_cfg.overrides.task))
    missed = missed_targets(plan.out / NUMBERS) if plan.check else []
    for line in missed:
        say(f"MISSED  {line}")
    if missed:
        sys.exit(1)


if __name__ == "__main__":
    run_cli(main, ReproduceJobCfg, config_name="reproduce", prepare=prepare_reproduce)
