"""Keep the placements the base can drive to (seed 000 V), on whichever map the scene gives.

One loop for every navigation map: :func:`drivable` asks a ``Route`` (goal pose -> path or None)
for each placement; :func:`map_route` plans on a segmented scene's navigation map (RRT or the region
graph), :func:`grid_route` on an occupancy grid with the cameras' obstacles marked (seed 004's grid
planner).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import BaseplaceError, InputError
from baseplace.geometry.poses import BasePose
from baseplace.navigation.gridnav import GridNavigator
from baseplace.navigation.navmap import NavigationMap
from baseplace.navigation.path import Path
from baseplace.navigation.planners import plan_path
from baseplace.placement.verified import Placement
from baseplace.world.grid_scene import with_cloud_obstacles
from baseplace.world.occupancy import OccupancyGrid

Route = Callable[[BasePose], Path | None]
"""Goal base pose -> the path from the robot's start to it, or None when there is none."""


@dataclass(frozen=True)
class Drivable:
    """The placements the base can drive to, in their order, with their paths.

    Attributes:
        placements: those with a path.
        paths: the path to each of them.
        unreachable: how many had none.
    """

    placements: list[Placement]
    paths: list[Path]
    unreachable: int


def drivable(placements: Sequence[Placement], route: Route) -> Drivable:
    """The placements ``route`` finds a path to, in order; the others counted."""
    paths = [route(p.pose) for p in placements]
    kept = [(p, r) for p, r in zip(placements, paths, strict=True) if r is not None]
    return Drivable([p for p, _ in kept], [r for _, r in kept], len(placements) - len(kept))


def map_route(navmap: NavigationMap, start: ArrayLike, planner: str, seed: int) -> Route:
    """Paths on a scene's navigation map from ``start`` (x [m], y [m], yaw [rad]) with ``planner`` (rrt, regions)."""
    s = np.asarray(start, dtype=float)

    def route(goal: BasePose) -> Path | None:
        try:
            return plan_path(navmap, s, np.array([goal.x, goal.y, goal.yaw]), planner, seed=seed)
        except BaseplaceError:
            return None

    return route


def grid_route(grid: OccupancyGrid, clouds: Sequence[ArrayLike], start: ArrayLike, radius: float) -> Route:
    """Paths on the occupancy grid, the cameras' obstacles marked, from ``start`` (x, y, yaw).

    The grid planner of seed 004 (:class:`~baseplace.navigation.gridnav.GridNavigator`, 8-connected,
    obstacles inflated by ``radius`` [m]); the clouds' points between 5 cm and 2 m above the floor are
    obstacles. Poses along a path head in the direction of travel; the first takes the start's yaw,
    the last the goal's.

    Raises:
        InputError: a start the robot cannot stand on (outside the map, unknown, too near an obstacle).
    """
    cams = [np.asarray(c, dtype=float).reshape(-1, 3) for c in clouds]
    navigator = GridNavigator(
        with_cloud_obstacles(grid, np.vstack(cams) if cams else np.zeros((0, 3))), radius
    )
    s = np.asarray(start, dtype=float)
    navigator.plan(s[:2], s[:2])  # a start the robot cannot stand on: the planner's one-line error
    s_pose = BasePose(*s)

    def route(goal: BasePose) -> Path | None:
        try:
            return navigator(s_pose, goal)
        except InputError:
            return None

    return route


__all__ = ["Drivable", "Route", "drivable", "grid_route", "map_route"]
