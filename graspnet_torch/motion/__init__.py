"""Reach motions: from a start configuration to the reported grasp, collision-free (OMPL, FCL) and
timed (Ruckig) (beyond the paper: its section 8's future work)."""

from graspnet_torch.motion.config import ReachCfg
from graspnet_torch.motion.reach import check_motion, check_start, plan_reach, start_posture
from graspnet_torch.motion.trajectory import Trajectory, time_path
from graspnet_torch.motion.validity import MotionChecker, StateLayout, state_postures

__all__ = ["MotionChecker", "ReachCfg", "StateLayout", "Trajectory", "check_motion", "check_start", "plan_reach",
           "start_posture", "state_postures", "time_path"]
