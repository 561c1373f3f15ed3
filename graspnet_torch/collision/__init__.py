"""Collisions between a robot and its environment (python-fcl): scenes and counts."""

from graspnet_torch.collision.geometry import fcl_geometry
from graspnet_torch.collision.scene import CollisionReport, CollisionScene, environment_obstacles, self_collision_pairs

__all__ = ["CollisionReport", "CollisionScene", "environment_obstacles", "fcl_geometry", "self_collision_pairs"]
