"""Train the FCNN (finger inverse kinematics experts) of every finger of a robot.

    python scripts/train_fcnn.py robot=hand
    python scripts/train_fcnn.py robot=hand fcnn.epochs=500 resume=true
    tensorboard --logdir outputs/train_fcnn/hand/tb

Exit status: 0 when it trained, 2 when the input was refused (one line on stderr), 130 when
Ctrl-C stopped it (one line: its state kept, resume with resume=true), 1 otherwise.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from graspnet_torch.jobs.cli import container, run_cli, user_errors_exit_2
from graspnet_torch.jobs.configs import TrainFCNNJobCfg
from graspnet_torch.jobs.train_fcnn import prepare_train, train_fcnn_job


@hydra.main(config_path="../configs", config_name="train_fcnn", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    train_fcnn_job(container(cfg), HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    run_cli(main, TrainFCNNJobCfg, config_name="train_fcnn", prepare=prepare_train)
