"""Collisions between a robot and its environment (python-fcl): scenes and counts."""

from graspnet_torch.collision.scene import CollisionReport, CollisionScene, fcl_geometry

__all__ = ["CollisionReport", "CollisionScene", "fcl_geometry"]
