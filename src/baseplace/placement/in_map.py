"""Placements from camera clouds plus a navigation map (seed 004's inputs, seed 000's method).

The occupancy grid gives the floor and its obstacles (:mod:`baseplace.world.grid_scene`), the
camera clouds the 3D shape near the targets (tables, shelves, objects); both, in one world frame,
go through seed 000's pipeline (:func:`baseplace.placement.pipeline.place`): segmentation, OSRM,
strategy, verification. The base may stand on the grid's free floor or on any support region of
the clouds; obstacles come from both.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.placement.pipeline import PlacementResult, PlaceSettings, place
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.terrain.diagnose import auto_resolution
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.grid_scene import GridSceneSettings, grid_points, target_window
from baseplace.world.obstacles import Obstacle
from baseplace.world.occupancy import OccupancyGrid


def scene_points_with_grid(
    clouds: Sequence[ArrayLike],
    grid: OccupancyGrid,
    targets_xy: ArrayLike,
    reach: float,
    resolution: float,
    settings: GridSceneSettings | None = None,
) -> np.ndarray:
    """The camera clouds (each (N_i, 3), world frame [m]) plus the grid's points near the targets (N, 2)."""
    s = settings or GridSceneSettings()
    cams = [np.asarray(c, dtype=float).reshape(-1, 3) for c in clouds]
    seen = np.vstack(cams) if cams else np.zeros((0, 3))
    window = target_window(grid, targets_xy, reach, s.margin)
    spacing = min(0.025, resolution)
    return np.vstack([seen, grid_points(grid, window, spacing, s, seen)])


def place_in_map(
    robot: Robot,
    rmap: ReachabilityMap,
    clouds: Sequence[ArrayLike],
    grid: OccupancyGrid,
    targets: ArrayLike,
    settings: PlaceSettings | None = None,
    rng: np.random.Generator | None = None,
    grid_settings: GridSceneSettings | None = None,
    grasped: GraspedObject | str | None = None,
    obstacles: Sequence[Obstacle] = (),
) -> PlacementResult:
    """Verified base placements from camera clouds and an occupancy grid in one world frame.

    Args:
        robot: the robot.
        rmap: reachability map of the arm to use.
        clouds: camera clouds, each (N_i, 3) [m] already in the world frame (world_T_camera
            applied); may be empty (the grid alone).
        grid: the navigation map in the same world frame, floor at z = 0.
        targets: (K, 4, 4) or (4, 4) world TCP targets.
        settings: placement settings; ``resolution=None`` takes the cell from the camera clouds
            (:func:`~baseplace.terrain.diagnose.auto_resolution`), or 5 cm without clouds.
        rng: randomness.
        grid_settings: how the grid becomes floor and obstacles.
        grasped: the object only the hand may touch, as in :func:`~baseplace.placement.pipeline.place`.
        obstacles: collision objects given by hand, as in :func:`~baseplace.placement.pipeline.place`.
    """
    s = settings or PlaceSettings()
    T = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    cams = [np.asarray(c, dtype=float).reshape(-1, 3) for c in clouds]
    cams = [c for c in cams if len(c)]
    resolution = s.resolution
    if resolution is None:
        resolution = auto_resolution(np.vstack(cams)) if cams else 0.05
    if not np.all(np.isfinite(T)):
        raise InputError("target pose contains NaN or infinity")
    points = scene_points_with_grid(cams, grid, T[:, :2, 3], rmap.horizontal_reach, resolution, grid_settings)
    return place(robot, rmap, points, T, dataclasses.replace(s, resolution=resolution), rng, grasped=grasped,
                 obstacles=obstacles)  # fmt: skip
