"""A standard grid planner on an occupancy grid: 8-connected Dijkstra with geometric step costs.

The robot is a disc of radius ``radius``. Cells with value >= :data:`OBSTACLE` are obstacles; the
grid is inflated by the radius (:meth:`OccupancyGrid.inflated`: every cell whose centre lies within
``radius`` of an obstacle cell centre is blocked), and the robot's centre may then move through
cells with ``0 <= value < OBSTACLE`` (and unknown cells, -1, when ``allow_unknown``). As in nav2's
inflation layer, only obstacle cells are inflated, not unknown ones. The search is scikit-image's
``MCP_Geometric`` (Dijkstra; axial steps cost one cell, diagonal steps sqrt(2) cells); a diagonal
step may pass between two blocked cells that touch at a corner, which the inflation makes safe
whenever ``radius`` >= one cell.

This is the navigation step of seed 004's pickup loop (section 3.3, Algorithm 2, where the robot
runs move_base); :mod:`baseplace.placement.candidates` uses it as the default ``Navigate``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from skimage.graph import MCP_Geometric

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, FloatArray, wrap_angle
from baseplace.navigation.path import Path
from baseplace.world.occupancy import UNKNOWN, OccupancyGrid

OBSTACLE = 50
"""Cells with a value >= this are obstacles (0..49 free; trinary maps hold only 0, 100 and -1)."""


def _point(xy: ArrayLike, what: str) -> FloatArray:
    p = np.asarray(xy, dtype=float).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise InputError(f"{what} must be 2 finite numbers (x, y) [m], got {np.asarray(xy).tolist()!r}")
    return p


def blocked_by_inflation(
    grid: OccupancyGrid, xy: ArrayLike, radius: float, allow_unknown: bool = False
) -> NDArray[np.bool_]:
    """(N,) whether the robot centre may not stand at world points ``xy`` (N, 2) [m].

    True off the map, on an obstacle cell, on an unknown cell (unless ``allow_unknown``) and on a
    cell whose centre lies within ``radius`` [m] of an obstacle cell centre: exactly the cells the
    planner of :meth:`GridNavigator.plan` cannot enter.
    """
    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    v = grid.value_at(pts)
    ok = grid.inside(pts) & (((v >= 0) & (v < OBSTACLE)) | (allow_unknown & (v == UNKNOWN)))
    cells = grid.clearance(pts, OBSTACLE) / grid.resolution  # same test as OccupancyGrid.inflated
    ok &= cells**2 > (radius / grid.resolution) ** 2 + 1e-9
    return ~ok


def _why_blocked(grid: OccupancyGrid, p: FloatArray, radius: float, allow_unknown: bool) -> str | None:
    if not grid.inside(p)[0]:
        return f"lies outside the map ({grid.width} x {grid.height} cells of {grid.resolution} m, origin {grid.origin})"
    v = int(grid.value_at(p)[0])
    if v >= OBSTACLE:
        return f"lies in an obstacle (cell value {v} >= {OBSTACLE})"
    if v == UNKNOWN and not allow_unknown:
        return "lies on an unknown cell; pass allow_unknown=True to plan through unknown space"
    if blocked_by_inflation(grid, p, radius, allow_unknown)[0]:
        c = float(grid.clearance(p, OBSTACLE)[0])
        return f"is too close to an obstacle (clearance {c:.3f} m <= robot radius {radius:.3f} m)"
    return None


@dataclass
class GridNavigator:
    """Plans paths for a disc robot on one occupancy grid, reusing the inflated grid between queries.

    Calling it as ``navigator(start, goal)`` with two :class:`BasePose` is seed 004's ``Navigate``
    (Algorithm 2, line 5): the path, or None when there is none.

    Attributes:
        grid: the occupancy grid.
        radius: robot radius [m] the obstacles are inflated by.
        allow_unknown: let the robot centre cross unknown (-1) cells.
    """

    grid: OccupancyGrid
    radius: float
    allow_unknown: bool = False
    _mcp: MCP_Geometric | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.radius) and self.radius >= 0):
            raise InputError(f"robot radius must be a finite number >= 0 m, got {self.radius}")

    @property
    def traversable(self) -> NDArray[np.bool_]:
        """(H, W) cells the robot centre may occupy (row 0 at the bottom, as ``grid.data``)."""
        v = self.grid.inflated(self.radius, OBSTACLE).data
        return ((v >= 0) & (v < OBSTACLE)) | (self.allow_unknown & (v == UNKNOWN))

    def _search(self) -> MCP_Geometric:
        if self._mcp is None:
            costs = np.where(self.traversable, 1.0, np.inf)
            res = self.grid.resolution
            self._mcp = MCP_Geometric(costs, fully_connected=True, sampling=(res, res))
        return self._mcp

    def _cell(self, xy: ArrayLike, what: str) -> tuple[FloatArray, tuple[int, int]]:
        p = _point(xy, what)
        why = _why_blocked(self.grid, p, self.radius, self.allow_unknown)
        if why is not None:
            raise InputError(f"{what} ({p[0]:.3f}, {p[1]:.3f}) {why}")
        col, row = self.grid.world_to_cell(p)[0]
        return p, (int(row), int(col))

    def plan(
        self,
        start_xy: ArrayLike,
        goal_xy: ArrayLike,
        start_yaw: float | None = None,
        goal_yaw: float | None = None,
    ) -> Path | None:
        """The shortest 8-connected path from start to goal, or None when the goal cannot be reached.

        None rather than an error, because the pickup loop tries the next candidate; the scanned
        scene's planner, :func:`baseplace.navigation.planners.plan_path`, raises instead. Both
        return the same :class:`~baseplace.navigation.path.Path`.

        Args:
            start_xy: (2,) start position in the map frame [m].
            goal_xy: (2,) goal position [m].
            start_yaw: the heading of the first pose [rad] (None: the direction of travel).
            goal_yaw: the heading of the last pose [rad] (None: the direction of travel).

        Returns:
            The path (planner "grid"): N >= 2 poses, the exact start, the centres of the cells in
            between, the exact goal; each heads in the direction of travel, the first and the last
            take ``start_yaw`` and ``goal_yaw`` when given.

        Raises:
            InputError: the start or the goal lies outside the map, in an obstacle, on an unknown
                cell (unless allowed), or within ``radius`` of an obstacle.
        """
        t0 = time.perf_counter()
        start, s = self._cell(start_xy, "start")
        goal, g = self._cell(goal_xy, "goal")
        if s == g:
            xy = np.array([start, goal])
        else:
            mcp = self._search()
            cost, _ = mcp.find_costs([s], [g], find_all_ends=True)
            if not np.isfinite(cost[g]):
                return None
            rows_cols = np.asarray(mcp.traceback(g), dtype=np.int64)
            xy = self.grid.cell_to_world(rows_cols[:, ::-1])
            xy[0], xy[-1] = start, goal
        step = np.diff(xy, axis=0)
        travel = np.arctan2(step[:, 1], step[:, 0])
        yaw = np.r_[travel, travel[-1]]
        if start_yaw is not None:
            yaw[0] = start_yaw
        if goal_yaw is not None:
            yaw[-1] = goal_yaw
        poses = np.c_[xy, wrap_angle(yaw)]
        return Path(poses, "grid", (time.perf_counter() - t0) * 1e3, ())

    def distances(self, start_xy: ArrayLike) -> FloatArray:
        """(H, W) path length [m] from the start cell's centre to every cell centre; inf where unreachable.

        Raises:
            InputError: as :meth:`plan` for the start.
        """
        _, s = self._cell(start_xy, "start")
        cost, _ = self._search().find_costs([s])
        return np.asarray(cost, dtype=float)

    def travel(self, start: BasePose, xy: ArrayLike) -> FloatArray:
        """(N,) path lengths [m] from ``start`` to world points ``xy`` (N, 2); inf where unreachable.

        Lengths run between cell centres. One Dijkstra search serves all points; points the robot
        cannot stand on are inf.
        """
        pts = np.asarray(xy, dtype=float).reshape(-1, 2)
        dist = self.distances((start.x, start.y))
        out = np.full(len(pts), np.inf)
        ok = ~blocked_by_inflation(self.grid, pts, self.radius, self.allow_unknown)
        cells = self.grid.world_to_cell(pts[ok])
        out[ok] = dist[cells[:, 1], cells[:, 0]]
        return out

    def __call__(self, start: BasePose, goal: BasePose) -> Path | None:
        """Seed 004's ``Navigate``: the path from ``start`` to ``goal`` (their headings at its ends), or None."""
        return self.plan((start.x, start.y), (goal.x, goal.y), start.yaw, goal.yaw)


__all__ = ["OBSTACLE", "GridNavigator", "blocked_by_inflation"]
