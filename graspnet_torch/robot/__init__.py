"""Robots: URDF + robot config -> chains, limits, frames and batched kinematics."""

from graspnet_torch.robot.chain import ChainSpec, UrdfModel
from graspnet_torch.robot.config import ChainCfg, PoseBounds, RobotCfg, available_robots, load_robot_cfg
from graspnet_torch.robot.frames import RobotLevels
from graspnet_torch.robot.kernel import ChainKernel
from graspnet_torch.robot.robot import Finger, Posture, Robot, load_robot

__all__ = [
    "ChainCfg",
    "ChainKernel",
    "ChainSpec",
    "Finger",
    "PoseBounds",
    "Posture",
    "Robot",
    "RobotCfg",
    "RobotLevels",
    "UrdfModel",
    "available_robots",
    "load_robot",
    "load_robot_cfg",
]
