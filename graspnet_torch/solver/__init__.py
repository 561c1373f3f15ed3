"""The closed loop of section 2.4, ``solve`` and ``solve_many``."""

from graspnet_torch.solver.api import solve, solve_many
from graspnet_torch.solver.config import CmaesCfg, FingersCfg, GripperCfg, NoiseCfg, PolishCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.solver.loop import LoopOutcome, run_loop
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.solver.session import Solver

__all__ = ["CmaesCfg", "FingersCfg", "GraspResult", "GripperCfg", "HandEnvironment", "LoopOutcome", "NoiseCfg",
           "PolishCfg", "RewardCfg", "Solver", "SolverCfg", "TrialResult", "run_loop", "solve", "solve_many"]
