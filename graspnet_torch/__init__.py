"""graspnet_torch: robotic grasp posture with a generic neural network architecture.

Rezzoug & Gorce, "Robotic Grasping: A Generic Neural Network Architecture": learned finger
inverse kinematics (FCNN) and a reinforcement-learning configuration network of Stochastic
Real-Valued units (HCNN / ACNN), in PyTorch.

    import graspnet_torch as gt
    robot = gt.load_robot("hand")
"""

from graspnet_torch.errors import CheckpointError, ConfigError, GraspnetError, ProblemError
from graspnet_torch.motion import ReachCfg, Trajectory, plan_reach
from graspnet_torch.physics import PhysicsCfg, PhysicsReport, check_until_failure, simulate_grasp
from graspnet_torch.quality import grasp_quality
from graspnet_torch.robot import Posture, Robot, load_robot
from graspnet_torch.solver import GraspResult, PolishCfg, RewardCfg, Solver, SolverCfg, solve, solve_many
from graspnet_torch.synthesis import SynthesizedGrasp, baseline_grasps, synthesize_grasps
from graspnet_torch.tasks import GraspProblem, Shape, random_reachable_problem
from graspnet_torch.threads import set_default_threads

__version__ = "0.1.0"

__all__ = [  # the user's names; the internals are in their subpackages (docs/python.md)
    "CheckpointError",
    "ConfigError",
    "GraspProblem",
    "GraspResult",
    "GraspnetError",
    "PhysicsCfg",
    "PhysicsReport",
    "PolishCfg",
    "Posture",
    "ProblemError",
    "ReachCfg",
    "RewardCfg",
    "Robot",
    "Shape",
    "Solver",
    "SolverCfg",
    "SynthesizedGrasp",
    "Trajectory",
    "__version__",
    "baseline_grasps",
    "check_until_failure",
    "grasp_quality",
    "load_robot",
    "plan_reach",
    "random_reachable_problem",
    "set_default_threads",
    "simulate_grasp",
    "solve",
    "solve_many",
    "synthesize_grasps",
]
