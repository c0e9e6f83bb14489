"""The obstacle space for base navigation across planar regions (seed 000, section V).

Seed 000 V: the environment voxels without the voxels of the planar regions are the obstacles,
and "all non-traversable edges e can be added to the obstacle space in form of a thin box from
p_s to p_e", so that conventional collision-based 2D planners never drive over a ledge. Here that
obstacle space is rasterized on the height map's grid:

* an obstacle voxel (see :func:`~baseplace.world.environment.obstacle_voxels`) blocks its cell
  when it lies between ``min_height`` and ``robot_height`` above the ground under it (the plane
  of the cell's region, else the lowest known height nearby): a table top above the robot's head
  would not block, a shelf at its waist does;
* every non-traversable region-graph edge is drawn as a line one cell thick;
* cells without any height data (outside the scan) are obstacles, since the robot cannot know
  there is ground there;
* a lone obstacle voxel with no other in its 3 x 3 cells is dropped as a noise outlier: with
  25 mm noise, a few floor points in a million land more than 8 cm off the plane;
* beyond the seed, every region cell within ``gap`` of another region that lies more than
  ``max_step`` above or below it there is an obstacle too: the graph's edge lines come from
  polygon sides and leave holes (corners, short stretches), and a platform lower than the
  support band has no wall voxels, so the lines alone let paths slip over ledges.

The base footprint is checked by its bounding circle against the Euclidean distance transform of
the obstacle raster: a pose is free when the nearest obstacle cell is farther than the radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import networkx as nx
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.graph import GraphSettings
from baseplace.terrain.pipeline import Terrain
from baseplace.terrain.segmentation import Segmentation
from baseplace.world.environment import SUPPORT_DIST, obstacle_voxels

ROBOT_HEIGHT = 1.6
"""Default height [m] of the space the moving robot sweeps (TIAGo: 1.1-1.45 m, PR2: 1.33-1.64 m)."""
MIN_HEIGHT = 0.05
"""Obstacle voxels lower than this above the ground [m] are sensor noise or drivable."""


@dataclass(frozen=True)
class NavigationMap:
    """Obstacle raster and clearance on the height map's grid.

    Attributes:
        seg: the segmentation (grid, labels, regions).
        obstacles: (H, W) bool, True where the base must not be.
        clearance: (H, W) distance [m] from each cell centre to the nearest obstacle cell centre.
        radius: the footprint's bounding radius [m].
        graph: the region graph the non-traversable edges came from.
    """

    seg: Segmentation
    obstacles: NDArray[np.bool_]
    clearance: FloatArray
    radius: float
    graph: nx.MultiGraph

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the grid [m]."""
        h, w = self.obstacles.shape
        x0, y0 = self.seg.hmap.origin
        r = self.seg.hmap.resolution
        return (x0, y0, x0 + w * r, y0 + h * r)

    def free(self, xy: FloatArray) -> NDArray[np.bool_]:
        """Whether the footprint's bounding circle at points (N, 2) is clear of every obstacle cell."""
        row, col, inside = self.seg.hmap.cell_of(np.asarray(xy, dtype=float).reshape(-1, 2))
        out = np.zeros(len(row), dtype=bool)
        out[inside] = self.clearance[row[inside], col[inside]] > self.radius
        return out

    def check_pose(self, name: str, xy: FloatArray) -> None:
        """Raise a clear InputError when a start or goal position (2,) cannot be driven from or to."""
        p = np.asarray(xy, dtype=float).reshape(1, 2)
        row, col, inside = self.seg.hmap.cell_of(p)
        x, y = p[0]
        if not inside[0]:
            x0, y0, x1, y1 = self.bounds
            raise InputError(
                f"{name} ({x:.2f}, {y:.2f}) is outside the scanned area x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}"
            )
        if self.seg.labels[row[0], col[0]] < 0:
            raise InputError(f"{name} ({x:.2f}, {y:.2f}) is off every surface: no planar region there")
        gap = float(self.clearance[row[0], col[0]])
        if gap <= self.radius:
            raise InputError(
                f"{name} ({x:.2f}, {y:.2f}) is in collision: an obstacle is {gap:.2f} m away, "
                f"within the footprint radius {self.radius:.2f} m"
            )


def navigation_map(
    terrain: Terrain,
    radius: float,
    robot_height: float = ROBOT_HEIGHT,
    min_height: float = MIN_HEIGHT,
    support_dist: float = SUPPORT_DIST,
    max_step: float = GraphSettings().max_step,
    gap: float = GraphSettings().gap,
) -> NavigationMap:
    """The obstacle space of seed 000 V for a footprint of bounding radius ``radius`` [m]."""
    if not (0.0 < radius < 5.0):
        raise InputError(f"footprint radius must be in (0, 5) m, got {radius}")
    if not (min_height < robot_height):
        raise InputError(f"robot_height ({robot_height}) must exceed min_height ({min_height})")
    seg, hmap = terrain.segmentation, terrain.segmentation.hmap
    h, w = seg.labels.shape
    ground = np.full((h, w), np.nan)
    rows, cols = np.nonzero(seg.labels >= 0)
    if len(rows):
        X, Y = hmap.cell_centres()
        xy = np.c_[X[rows, cols], Y[rows, cols]]
        for region in seg.regions:
            sel = seg.labels[rows, cols] == region.id
            ground[rows[sel], cols[sel]] = region.height_at(xy[sel])
    raw = np.where(np.isnan(hmap.raw), np.inf, hmap.raw)
    lowest = ndimage.minimum_filter(raw, size=11, mode="nearest")  # the ground beside objects and walls
    ground = np.where(np.isnan(ground), lowest, ground)
    obstacles = np.isnan(hmap.raw).copy()  # no data: no known ground
    vox = obstacle_voxels(terrain.voxels, seg, support_dist).centres
    if len(vox):
        r, c, inside = hmap.cell_of(vox[:, :2])
        rel = vox[inside, 2] - ground[r[inside], c[inside]]
        hit = (rel >= min_height) & (rel <= robot_height)
        count = np.zeros((h, w))
        np.add.at(count, (r[inside][hit], c[inside][hit]), 1.0)
        # A lone voxel with no other in its 3 x 3 cells is a noise outlier (3+ sigma off its plane).
        neighbourhood = ndimage.uniform_filter(count, size=3, mode="constant") * 9.0
        obstacles |= (count > 0) & (neighbourhood > 1.5)
    lines = np.zeros((h, w), dtype=np.uint8)
    for _, _, data in terrain.graph.edges(data=True):
        if not data["traversable"]:
            (c0, r0), (c1, r1) = (
                (np.asarray(p) - np.asarray(hmap.origin)) / hmap.resolution
                for p in (data["p_s"], data["p_e"])
            )
            cv2.line(lines, (int(c0), int(r0)), (int(c1), int(r1)), 1, thickness=1)
    obstacles |= lines.astype(bool)
    obstacles |= _ledges(seg, max_step, gap)
    clearance = ndimage.distance_transform_edt(~obstacles) * hmap.resolution
    return NavigationMap(seg, obstacles, clearance, float(radius), terrain.graph)


def _ledges(seg: Segmentation, max_step: float, gap: float) -> NDArray[np.bool_]:
    """Outermost region cells within ``gap`` of another region more than ``max_step`` above or below.

    For a cell p of one region near region r, the step is the height of p on its own plane
    against the height of r's nearest cell q on r's plane: where a ramp's low edge meets the floor
    it is about zero, along the ramp's sides it is the side's height. Marking every such cell
    closes the holes that a border drawn from polygon sides leaves (short stretches below
    ``min_border_cells``, corners, low platforms whose walls fall inside the support band).
    """
    hmap = seg.hmap
    X, Y = hmap.cell_centres()
    reach = gap + hmap.resolution * 1.5
    out = np.zeros(seg.labels.shape, dtype=bool)
    own = np.full(seg.labels.shape, np.nan)
    for r in seg.regions:
        m = seg.labels == r.id
        own[m] = r.height_at(np.c_[X[m], Y[m]])
    labelled = seg.labels >= 0
    # the outermost cells of every region: a ledge is marked one cell thick, on each side
    lo = ndimage.grey_erosion(seg.labels, size=3, mode="nearest")
    hi = ndimage.grey_dilation(seg.labels, size=3, mode="nearest")
    outline = labelled & ((lo != seg.labels) | (hi != seg.labels))
    for r in seg.regions:
        dist, (qi, qj) = ndimage.distance_transform_edt(seg.labels != r.id, return_indices=True)
        near = (dist * hmap.resolution <= reach) & outline & (seg.labels != r.id)
        rows, cols = np.nonzero(near)
        step = np.abs(own[rows, cols] - own[qi[rows, cols], qj[rows, cols]])
        out[rows[step > max_step], cols[step > max_step]] = True
    return out
