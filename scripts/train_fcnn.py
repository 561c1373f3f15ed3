"""Train the FCNN (finger inverse kinematics experts) of every finger of a robot.

    python scripts/train_fcnn.py robot=hand
    python scripts/train_fcnn.py robot=hand fcnn.epochs=500 resume=true
    tensorboard --logdir outputs/train_fcnn/hand/tb
"""

from __future__ import annotations

import sys

import hydra
import torch
from omegaconf import DictConfig, OmegaConf

from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.jobs.cli import check_group_overrides, user_errors_exit_2
from graspnet_torch.jobs.train_fcnn import train_fcnn
from graspnet_torch.robot import Robot, RobotCfg


@hydra.main(config_path="../configs", config_name="train_fcnn", version_base="1.3")
@user_errors_exit_2
def main(cfg: DictConfig) -> None:
    torch.set_num_threads(cfg.threads)
    robot = Robot(RobotCfg.from_mapping(OmegaConf.to_container(cfg.robot), source=f"robot={cfg.robot.name}"))
    fcnn = FCNNTrainCfg.from_mapping(OmegaConf.to_container(cfg.fcnn))
    train_fcnn(robot, fcnn, hydra.core.hydra_config.HydraConfig.get().runtime.output_dir, seed=cfg.seed,
               fingers=cfg.fingers, resume=cfg.resume, export=cfg.export, checkpoint_every=cfg.checkpoint_every,
               progress=cfg.progress, eval_targets=cfg.eval_targets)


if __name__ == "__main__":
    check_group_overrides(sys.argv[1:], ("robot", "fcnn"))
    main()
