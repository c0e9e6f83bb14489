"""The robot's surroundings: obstacle voxels for collision checks."""

from baseplace.world.environment import Environment, HandFilter, obstacle_voxels

__all__ = ["Environment", "HandFilter", "obstacle_voxels"]
