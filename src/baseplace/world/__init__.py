"""The robot's surroundings: obstacle voxels and obstacles given by hand for collision checks, and the grasped object."""

from baseplace.world.environment import Environment, HandFilter, contact_groups, obstacle_voxels
from baseplace.world.grasped_object import GraspedObject, find_grasped_object, parse_grasped_object
from baseplace.world.obstacles import Obstacle, parse_obstacles

__all__ = [
    "Environment",
    "GraspedObject",
    "HandFilter",
    "Obstacle",
    "contact_groups",
    "find_grasped_object",
    "obstacle_voxels",
    "parse_grasped_object",
    "parse_obstacles",
]
