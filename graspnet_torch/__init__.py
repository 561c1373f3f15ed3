"""graspnet_torch: robotic grasp posture with a generic neural network architecture.

Rezzoug & Gorce, "Robotic Grasping: A Generic Neural Network Architecture": learned finger
inverse kinematics (FCNN) and a reinforcement-learning configuration network of Stochastic
Real-Valued units (HCNN / ACNN), in PyTorch.

    import graspnet_torch as gt
    robot = gt.load_robot("hand")
"""

from graspnet_torch.errors import CheckpointError, ConfigError, GraspnetError, InternalError, ProblemError
from graspnet_torch.fcnn import ExpertSet, ExpertSetCfg, FCNNTrainCfg, FingerIK, load_finger_ik
from graspnet_torch.motion import ReachCfg, Trajectory, check_motion, plan_reach
from graspnet_torch.physics import PhysicsCfg, PhysicsReport, check_until_failure, simulate_grasp
from graspnet_torch.quality import GraspQuality, grasp_quality
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
from graspnet_torch.solver import (
    CmaesCfg,
    FingersCfg,
    GraspResult,
    GripperCfg,
    NoiseCfg,
    PolishCfg,
    RewardCfg,
    Solver,
    SolverCfg,
    TrialResult,
    solve,
    solve_many,
)
from graspnet_torch.solver.kinds import KINDS, RobotKind, robot_kind  # registers the robot kinds
from graspnet_torch.srv import ConfigurationNetwork, SigmaCfg, SRVFunction, SRVNetCfg
from graspnet_torch.synthesis import (
    BaselineGrasp,
    ContactSet,
    SynthesizedGrasp,
    baseline_grasps,
    pad_contact_sets,
    synthesize_grasps,
)
from graspnet_torch.tasks import (
    Contact,
    GraspProblem,
    Shape,
    available_tasks,
    random_reachable_problem,
    random_sequence,
)
from graspnet_torch.threads import set_default_threads

__version__ = "0.1.0"

__all__ = [
    "KINDS",
    "BaselineGrasp",
    "ChainKernel",
    "ChainSpec",
    "CheckpointError",
    "CmaesCfg",
    "ConfigError",
    "ConfigurationNetwork",
    "Contact",
    "ContactSet",
    "ExpertSet",
    "ExpertSetCfg",
    "FCNNTrainCfg",
    "FingerIK",
    "FingersCfg",
    "GraspProblem",
    "GraspQuality",
    "GraspResult",
    "GraspnetError",
    "GripperCfg",
    "InternalError",
    "NoiseCfg",
    "PhysicsCfg",
    "PhysicsReport",
    "PolishCfg",
    "PoseBounds",
    "Posture",
    "ProblemError",
    "ReachCfg",
    "RewardCfg",
    "Robot",
    "RobotCfg",
    "RobotKind",
    "SRVFunction",
    "SRVNetCfg",
    "Shape",
    "SigmaCfg",
    "Solver",
    "SolverCfg",
    "SynthesizedGrasp",
    "Trajectory",
    "TrialResult",
    "__version__",
    "available_robots",
    "available_tasks",
    "baseline_grasps",
    "check_motion",
    "check_until_failure",
    "grasp_quality",
    "load_finger_ik",
    "load_robot",
    "load_robot_cfg",
    "pad_contact_sets",
    "plan_reach",
    "random_reachable_problem",
    "random_sequence",
    "robot_kind",
    "set_default_threads",
    "simulate_grasp",
    "solve",
    "solve_many",
    "synthesize_grasps",
]
