"""graspnet_torch: robotic grasp posture with a generic neural network architecture.

Rezzoug & Gorce, "Robotic Grasping: A Generic Neural Network Architecture": learned finger
inverse kinematics (FCNN) and a reinforcement-learning configuration network of Stochastic
Real-Valued units (HCNN / ACNN), in PyTorch.

    import graspnet_torch as gt
    robot = gt.load_robot("hand")
"""

from graspnet_torch.errors import CheckpointError, ConfigError, GraspnetError, ProblemError
from graspnet_torch.fcnn import ExpertSet, ExpertSetCfg, FCNNTrainCfg, FingerIK, load_finger_ik
from graspnet_torch.robot import (
    ChainKernel,
    ChainSpec,
    PoseBounds,
    Posture,
    Robot,
    RobotCfg,
    available_robots,
    load_robot,
    load_robot_cfg,
)

__version__ = "0.1.0"

__all__ = [
    "ChainKernel",
    "ChainSpec",
    "CheckpointError",
    "ConfigError",
    "ExpertSet",
    "ExpertSetCfg",
    "FCNNTrainCfg",
    "FingerIK",
    "GraspnetError",
    "PoseBounds",
    "Posture",
    "ProblemError",
    "Robot",
    "RobotCfg",
    "__version__",
    "available_robots",
    "load_finger_ik",
    "load_robot",
    "load_robot_cfg",
]
