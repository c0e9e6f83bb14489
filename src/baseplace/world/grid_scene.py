"""A navigation map and camera clouds as one scene (seed 004 combines an occupancy grid and an RGB-D cloud).

A head camera rarely sees the floor the base stands on; the robot's navigation map knows it. The
grid becomes points, so that one segmentation and one collision model serve both inputs:

* every free cell (0 <= value < ``free_below``) in the window becomes floor points at z = 0, one
  per voxel: a planar region the base may stand on;
* every occupied cell (value >= ``occupied_from``) becomes a column of points from the floor to
  ``obstacle_height``: an obstacle for the footprint and the arm;
* unknown cells give nothing: no floor to stand on;
* where a camera saw the cell (a point of the cloud above it; holes of up to two cells closed), the
  cloud's own 3D shape replaces the grid's: its floor, a table over the floor (floor points would
  fill the holes of a stereo image of the table and break its plane), a table's outline that the
  map marks occupied but that the arm can reach over.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.world.occupancy import OccupancyGrid

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GridSceneSettings:
    """How a grid becomes points.

    Attributes:
        free_below: cells with 0 <= value < this are free floor (nav2: 0 free, 100 lethal).
        occupied_from: cells with value >= this are obstacles.
        obstacle_height: height of an occupied cell's column [m].
        margin: the window around the targets reaches this far beyond the arm's reach [m].
    """

    free_below: int = 50
    occupied_from: int = 65
    obstacle_height: float = 2.0
    margin: float = 1.0


def grid_points(
    grid: OccupancyGrid,
    window: tuple[float, float, float, float],
    spacing: float,
    settings: GridSceneSettings | None = None,
    seen: ArrayLike | None = None,
) -> FloatArray:
    """Floor and obstacle points (N, 3) [m] of the grid's cells inside ``window``.

    Args:
        grid: the occupancy grid, its frame the world frame, floor at z = 0.
        window: (x_min, y_min, x_max, y_max) [m] in the world frame.
        spacing: distance between the points [m] (the voxel size, so every voxel is filled).
        settings: thresholds and column height.
        seen: (M, 3) camera points in the world frame; the grid gives nothing under them.
    """
    s = settings or GridSceneSettings()
    if not (0.001 <= spacing <= 1.0):
        raise InputError(f"grid point spacing must be in [0.001, 1] m, got {spacing}")
    x0, y0, x1, y1 = window
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"empty window {window}")
    n = math.ceil((x1 - x0) / spacing) * math.ceil((y1 - y0) / spacing)
    if n > 20_000_000:
        raise InputError(
            f"the window {window} holds {n} floor points at {spacing} m; give fewer or nearer targets"
        )
    gx = np.arange(math.floor(x0 / spacing), math.ceil(x1 / spacing)) * spacing + spacing / 2
    gy = np.arange(math.floor(y0 / spacing), math.ceil(y1 / spacing)) * spacing + spacing / 2
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    xy = np.c_[X.ravel(), Y.ravel()]
    inside = grid.inside(xy)
    xy = xy[inside]
    values = grid.value_at(xy).astype(np.int16)
    free = (values >= 0) & (values < s.free_below)
    occupied = values >= s.occupied_from
    if seen is not None:
        covered = _seen_cells(grid, np.asarray(seen, dtype=float).reshape(-1, 3))
        ij = grid.world_to_cell(xy)
        under = covered[ij[:, 1], ij[:, 0]]
        free &= ~under
        occupied &= ~under
    floor = np.c_[xy[free], np.zeros(int(free.sum()))]
    heights = np.arange(spacing / 2, s.obstacle_height, spacing)
    cols = xy[occupied]
    walls = np.c_[np.repeat(cols, len(heights), axis=0), np.tile(heights, len(cols))]
    return np.vstack([floor, walls]) if len(walls) else floor


def _seen_cells(grid: OccupancyGrid, seen: FloatArray) -> NDArray[np.bool_]:
    """(H, W) cells a camera saw, holes of up to two cells closed (stereo and depth images have holes)."""
    from scipy import ndimage

    mask = np.zeros(grid.data.shape, dtype=bool)
    if len(seen):
        ij = grid.world_to_cell(seen[:, :2])
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < grid.width) & (ij[:, 1] >= 0) & (ij[:, 1] < grid.height)
        mask[ij[ok, 1], ij[ok, 0]] = True
        mask = ndimage.binary_closing(mask, iterations=2, border_value=0) | mask
    return mask


def with_cloud_obstacles(
    grid: OccupancyGrid, points: ArrayLike, z_min: float = 0.05, z_max: float = 2.0
) -> OccupancyGrid:
    """The grid with every cell under a cloud point between ``z_min`` and ``z_max`` [m] occupied.

    For planning the base on the map: a table or a chair that the cameras see but the map does not
    show blocks the path (points (N, 3) in the grid's world frame, floor at z = 0).
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    pts = pts[(pts[:, 2] > z_min) & (pts[:, 2] < z_max)]
    data = grid.data.copy()
    if len(pts):
        ij = grid.world_to_cell(pts[:, :2])
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < grid.width) & (ij[:, 1] >= 0) & (ij[:, 1] < grid.height)
        data[ij[ok, 1], ij[ok, 0]] = 100
    return OccupancyGrid(data, grid.resolution, grid.origin, grid.source)


def target_window(
    grid: OccupancyGrid, targets_xy: ArrayLike, reach: float, margin: float
) -> tuple[float, float, float, float]:
    """The part of the grid within ``reach + margin`` [m] of the targets (N, 2), clipped to the grid."""
    xy = np.asarray(targets_xy, dtype=float).reshape(-1, 2)
    w, h = grid.width - 0.5, grid.height - 0.5
    corners = grid.cell_to_world(np.array([[-0.5, -0.5], [w, -0.5], [-0.5, h], [w, h]]))
    gx0, gy0 = corners.min(axis=0)
    gx1, gy1 = corners.max(axis=0)
    r = reach + margin
    x0, y0 = np.maximum(xy.min(axis=0) - r, [gx0, gy0])
    x1, y1 = np.minimum(xy.max(axis=0) + r, [gx1, gy1])
    if not (x1 > x0 and y1 > y0):
        raise InputError("the targets lie outside the occupancy grid")
    return float(x0), float(y0), float(x1), float(y1)
