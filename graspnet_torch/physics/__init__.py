"""The physics check of a grasp in MuJoCo (``gt.simulate_grasp``): does the grasp hold its object?

DexGraspBench's protocol: friction 0.6 tangential / 0.02 torsional, elliptic cones, object 100 g,
timestep 4 ms, an external force of the object's weight along +-x, +-y, +-z in turn for 2 s each;
holds when the object moves less than 5 cm and turns less than 15 degrees
(:mod:`~graspnet_torch.physics.config`). MuJoCo is optional (``pip install mujoco``): imported only
when a check runs.
"""

from graspnet_torch.physics.check import PhysicsReport, check_until_failure, simulate_grasp
from graspnet_torch.physics.config import DIRECTIONS, PhysicsCfg

__all__ = ["DIRECTIONS", "PhysicsCfg", "PhysicsReport", "check_until_failure", "simulate_grasp"]
