"""Train a robot's posture proposal model (the configurations the SRV loop starts from).

    python scripts/train_posture.py robot=hand
    python scripts/train_posture.py robot=examples/trifinger/trifinger.yaml posture.steps=3000 resume=true
    tensorboard --logdir outputs/train_posture/hand/tb

Exit status: 0 when it trained, 2 when the input was refused (one line on stderr), 130 when
Ctrl-C stopped it (one line: its state kept, resume with resume=true), 1 otherwise.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import TrainPostureJobCfg
from graspnet_torch.jobs.train_posture import prepare_train_posture, train_posture_job


@hydra.main(config_path="../configs", config_name="train_posture", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    train_posture_job(container(cfg), HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    run_cli(main, TrainPostureJobCfg, config_name="train_posture", prepare=prepare_train_posture)
