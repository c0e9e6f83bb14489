"""The robot's surroundings: obstacle voxels for collision checks."""

from baseplace.world.environment import Environment, obstacle_voxels

__all__ = ["Environment", "obstacle_voxels"]
