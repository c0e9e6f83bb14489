"""The robot's surroundings: obstacle voxels and obstacles given by hand for collision checks, and the grasped object."""

from __future__ import annotations

from typing import TYPE_CHECKING

from baseplace.lazy import lazy_getattr

if TYPE_CHECKING:
    from baseplace.world.environment import Environment, HandFilter, contact_groups, obstacle_voxels
    from baseplace.world.grasped_object import GraspedObject, find_grasped_object, parse_grasped_object
    from baseplace.world.obstacles import Obstacle, parse_obstacles

_LAZY = {
    "Environment": "baseplace.world.environment", "HandFilter": "baseplace.world.environment",
    "contact_groups": "baseplace.world.environment", "obstacle_voxels": "baseplace.world.environment",
    "GraspedObject": "baseplace.world.grasped_object", "find_grasped_object": "baseplace.world.grasped_object",
    "parse_grasped_object": "baseplace.world.grasped_object",
    "Obstacle": "baseplace.world.obstacles", "parse_obstacles": "baseplace.world.obstacles",
}  # fmt: skip
"""Public name -> its module, imported on first use (PEP 562): reading an occupancy grid never
imports the collision model (coal, pinocchio, scipy's trees)."""

__getattr__ = lazy_getattr(__name__, _LAZY, globals())

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
