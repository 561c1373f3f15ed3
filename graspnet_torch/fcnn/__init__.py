"""FCNN: learned finger inverse kinematics by modular experts (paper section 3)."""

from graspnet_torch.fcnn.checkpoint import load_finger_ik, save_finger_ik
from graspnet_torch.fcnn.dataset import TrainingSet
from graspnet_torch.fcnn.experts import ExpertSet, ExpertSetCfg
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.fcnn.reach import ReachCfg, ReachResult, reach_motion
from graspnet_torch.fcnn.train import FCNNTrainCfg, FingerTrainer

__all__ = [
    "ExpertSet",
    "ExpertSetCfg",
    "FCNNTrainCfg",
    "FingerIK",
    "FingerTrainer",
    "ReachCfg",
    "ReachResult",
    "TrainingSet",
    "load_finger_ik",
    "reach_motion",
    "save_finger_ik",
]
