"""The closed loop of section 2.4, ``solve`` and ``solve_many``."""

from graspnet_torch.solver.api import solve, solve_many
from graspnet_torch.solver.config import NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.hand import HandEnvironment
from graspnet_torch.solver.loop import LoopOutcome, run_loop
from graspnet_torch.solver.result import GraspResult, TrialResult

__all__ = ["GraspResult", "HandEnvironment", "LoopOutcome", "NoiseCfg", "RewardCfg", "SolverCfg", "TrialResult",
           "run_loop", "solve", "solve_many"]
