"""Inverse surface reachability maps for working surfaces (seed 002, section III).

Where should the robot stand to work on a whole table before it knows where the objects are?

* The **point map** (seed 002 III) gives, for base poses (x, y, theta) relative to a point at
  height h, the reachability index R_P of that point. Here R_P is 1 where the reachability map
  has a reached orientation bin at the point's voxel among the *allowed* bins (those whose
  approach axis lies within ``cone`` of straight down, "approach from above", or all bins), and
  0 elsewhere. With this choice R_S below is exactly what seed 002 says it "intuitively
  corresponds to": the share of the surface the robot reaches from the pose. Restricting to
  approaches from above keeps the map from counting grasps through the surface from below.
* The **surface map** accumulates R_P over the grid points inside the polygon and normalizes by
  their number n (eq. 2): ``R_S(b) = 1/n sum_g R_P(b - g)``. The point map and the surface map
  share resolution and alignment, so for each theta this sum is the convolution of the polygon's
  mask with the point map, computed with an FFT (:func:`scipy.signal.fftconvolve`). Poses whose
  footprint overlaps the surface's footprint (the furniture under it) are invalid and get 0.
* Arms combine by max ("any": either arm reaches) or min ("both": two-handed work).

The arm chains of the built-in robots include the torso lift, so the base has no z levels: the
base frame stands on the floor (z = 0) and the torso height is part of the reachability map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, unknown
from baseplace.geometry.poses import FloatArray
from baseplace.guards import check_alloc, check_grid_size
from baseplace.placement.osrm import footprint_kernel
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.terrain.polygons import MAX_COORDINATE as MAX_COORDINATE
from baseplace.terrain.polygons import footprint_outline
from baseplace.terrain.polygons import parse_polygon as parse_polygon

COMBINE = {"any": np.maximum, "both": np.minimum}
"""How per-arm surface maps combine: "any" arm reaches (max) or "both" arms reach (min)."""
AXES = {"x": 0, "y": 1, "z": 2}
FACE_NUDGE = 1e-6
"""Grid points often fall exactly on voxel faces; this nudge [voxels] puts them in the upper voxel
whatever the round-off of the rotation."""
TCP_HEIGHT = 0.05
"""Height [m] of the TCP above the surface where it works: grasping a small object standing there."""


def allowed_bins(
    rmap: ReachabilityMap, cone: float | None, approach_axis: str | ArrayLike = "x"
) -> NDArray[np.bool_]:
    """Orientation bins (n_orientations,) whose TCP approach axis lies within ``cone`` [rad] of down.

    ``cone=None`` allows every bin. The approach axis is an axis name or a (3,) unit vector in
    the TCP frame: the arm's ``approach_axis`` (x for the built-in robots' ``arm_tool_link`` and
    ``*_gripper_tool_frame``, z for a UR ``tool0`` or Panda's ``panda_hand_tcp``).
    """
    if isinstance(approach_axis, str):
        if approach_axis not in AXES:
            raise unknown("approach axis", approach_axis, AXES)
        approach_axis = np.eye(3)[AXES[approach_axis]]
    axis = np.asarray(approach_axis, dtype=float)
    n = rmap.grid.n_orientations
    if cone is None:
        return np.ones(n, dtype=bool)
    if not 0.0 < cone <= math.pi:
        raise InputError(f"approach cone must be in (0, pi] rad, got {cone}")
    R = rmap.grid.orientation_centre(np.arange(n))
    return R[:, 2, :] @ axis <= -math.cos(cone)  # the world z component of the approach direction


def point_map(
    rmap: ReachabilityMap,
    height: float,
    resolution: float,
    thetas: FloatArray,
    cone: float | None = math.pi / 4,
    approach_axis: str | ArrayLike = "x",
) -> tuple[NDArray[np.float32], float]:
    """R_P of a point at ``height`` over base offsets (dx, dy) = base - point and headings.

    Args:
        rmap: the arm's reachability map (TCP poses relative to the base frame on the floor).
        height: the point's height above the floor [m].
        resolution: grid spacing of the offsets [m].
        thetas: (T,) base headings [rad].
        cone: approach cone about straight down [rad], or None for any orientation.
        approach_axis: the TCP's approach axis, see :func:`allowed_bins`.

    Returns:
        ((T, K, K) values in {0, 1}, half-width [m]): offsets run from -half to +half in steps of
        ``resolution`` along both axes (x first).
    """
    offset, blocks = rmap.tables
    # a cell counts if its centre passes the map's support test (any reached cell without one)
    ok: NDArray[np.bool_] = np.asarray(
        (blocks[:, allowed_bins(rmap, cone, approach_axis)] >= rmap.cell_floor).any(axis=1)
    )
    voxel_ok = np.zeros(len(offset), dtype=bool)
    voxel_ok[offset >= 0] = ok[offset[offset >= 0]]
    k = math.ceil(rmap.horizontal_reach / resolution)
    d = np.arange(-k, k + 1) * resolution
    DX, DY = np.meshgrid(d, d, indexing="ij")
    grid = rmap.grid
    out = np.zeros((len(thetas), len(d), len(d)), dtype=np.float32)
    for t, theta in enumerate(thetas):
        c, s = math.cos(theta), math.sin(theta)
        # the point (0, 0, h) seen from a base at (dx, dy) heading theta: Rz(-theta) @ (-dx, -dy)
        px, py = -(c * DX + s * DY), -(-s * DX + c * DY)
        ijk = np.stack([px, py, np.full_like(px, height)], axis=-1) - np.asarray(grid.origin)
        ijk = np.floor(ijk / grid.voxel_size + FACE_NUDGE).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < np.asarray(grid.shape)), axis=-1)
        flat = np.ravel_multi_index(tuple(np.where(inside[..., None], ijk, 0).transpose(2, 0, 1)), grid.shape)
        out[t] = np.where(inside, voxel_ok[flat], False)
    return out, k * resolution


@dataclass(frozen=True)
class SurfaceMap:
    """R_S over base poses (x, y, theta) around a polygonal working surface.

    Attributes:
        values: (T, NX, NY) R_S in [0, 1]; ``values[t, i, j]`` is the pose at
            ``origin + (i, j) * resolution`` heading ``thetas[t]``.
        origin: (x, y) of cell (0, 0)'s centre [m].
        resolution: cell size [m].
        polygon: (N, 2) the surface's vertices [m].
        height: the surface's height [m].
        robot: robot name.
        arms: the arms combined.
        combine: "any" (max over arms) or "both" (min).
        cone: approach cone [rad], or None for any orientation.
        tcp_height: height [m] of the TCP above the surface in the point maps.
    """

    values: NDArray[np.float32]
    origin: tuple[float, float]
    resolution: float
    polygon: FloatArray
    height: float
    robot: str
    arms: tuple[str, ...]
    combine: str
    cone: float | None
    tcp_height: float = TCP_HEIGHT

    @property
    def thetas(self) -> FloatArray:
        """(T,) headings [rad], evenly spaced from 0."""
        return np.arange(len(self.values), dtype=np.float64) * (2 * math.pi / len(self.values))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) [m] of the map's cells, edges included."""
        h = self.resolution / 2
        _, nx, ny = self.values.shape
        x0, y0 = self.origin
        return (x0 - h, y0 - h, x0 + (nx - 1) * self.resolution + h, y0 + (ny - 1) * self.resolution + h)

    def reachability(self, poses: ArrayLike) -> NDArray[np.float32]:
        """R_S of base poses (N, 3) or (3,) as (x, y, theta): a constant-time nearest-cell lookup; 0 outside."""
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        n_t, nx, ny = self.values.shape
        i = np.rint((p[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        j = np.rint((p[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        t = np.rint(p[:, 2] / (2 * math.pi / n_t)).astype(np.int64) % n_t
        inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
        out = np.zeros(len(p), dtype=np.float32)
        out[inside] = self.values[t[inside], i[inside], j[inside]]
        return out

    def cell_poses(self) -> tuple[FloatArray, NDArray[np.float32]]:
        """Every pose with R_S > 0 as (M, 3) (x, y, theta) and its (M,) values."""
        t, i, j = np.nonzero(self.values)
        xy = np.asarray(self.origin) + np.c_[i, j] * self.resolution
        return np.c_[xy, self.thetas[t]], self.values[t, i, j]

    def summary(self) -> dict[str, Any]:
        """Plain description for JSON output."""
        return {
            "robot": self.robot, "arms": list(self.arms), "combine": self.combine,
            "polygon": self.polygon.tolist(), "height": self.height, "resolution": self.resolution,
            "orientations": len(self.values), "shape": list(self.values.shape[1:]),
            "origin": list(self.origin), "nonzero_poses": int(np.count_nonzero(self.values)),
            "max": float(self.values.max()), "cone_rad": self.cone, "tcp_height": self.tcp_height,
        }  # fmt: skip


BYTES_PER_POSE = 32.0
"""Peak bytes per (heading, x, y) cell of a build: the float32 results of the FFTs, stacked,
clipped and combined over arms, and the index and values of the sparse save."""
BYTES_PER_FLOOR_CELL = 128.0
"""Peak bytes per (x, y) cell, whatever the headings: the surface's grid points and their indices
(measured: 112 with one heading), or the footprint test's raster at 1/8 cell (64)."""


def check_surface_grid(polygon: FloatArray, resolution: float, orientations: int, margin: float = 0.0) -> int:
    """Check a surface map's settings and its grid's size before anything is allocated; returns its cells.

    The grid covers the polygon's bounding box on multiples of ``resolution``, widened by
    ``margin`` [m] on every side (the arms' horizontal reach), times ``orientations`` headings.
    Its peak memory, :data:`BYTES_PER_POSE` per cell and :data:`BYTES_PER_FLOOR_CELL` per (x, y)
    cell, must fit ``$BASEPLACE_MAX_MEMORY_MB`` (:func:`~baseplace.guards.memory_cap_bytes`).

    Args:
        polygon: (N, 2) vertices [m], as :func:`parse_polygon` returns them.
        resolution: grid spacing [m], 0.01 to 0.5.
        orientations: base headings, 1 to 360.
        margin: how far the grid reaches beyond the polygon [m] (0: the polygon's box only).

    Raises:
        InputError: a resolution or orientation count out of range, or a grid over the limit,
            with its cell count and the limit.
    """
    if not (0.01 <= resolution <= 0.5):
        raise InputError(f"resolution must be between 0.01 and 0.5 m, got {resolution}")
    if not (1 <= orientations <= 360):
        raise InputError(f"orientations must be between 1 and 360, got {orientations}")
    k = math.ceil(margin / resolution)
    lo = np.floor(polygon.min(axis=0) / resolution)
    hi = np.ceil(polygon.max(axis=0) / resolution)
    nx, ny = (float(v) + 1 + 2 * k for v in hi - lo)
    per_cell = BYTES_PER_POSE + BYTES_PER_FLOOR_CELL / orientations
    cells = orientations * nx * ny
    check_grid_size(
        cells, per_cell, f"the surface map's grid of {orientations} headings x {nx:.0f} x {ny:.0f} = {cells:.3g} cells",
        "use a coarser --resolution, fewer --orientations or a smaller polygon",
    )  # fmt: skip
    return int(cells)


GRID_BYTES_PER_CELL = 112.0
"""Peak bytes per cell of the polygon's bounding box in :func:`surface_grid` (measured: about 100)."""


def surface_grid(polygon: FloatArray, resolution: float) -> FloatArray:
    """Grid points (n, 2) inside the polygon, on multiples of ``resolution`` [m].

    Raises:
        InputError: the polygon's bounding box holds more cells than the memory cap allows.
    """
    lo = np.floor(polygon.min(axis=0) / resolution).astype(int)
    hi = np.ceil(polygon.max(axis=0) / resolution).astype(int)
    n_cells = float(np.prod((hi - lo + 1).astype(float)))
    check_alloc(
        n_cells * GRID_BYTES_PER_CELL, f"the {n_cells:.3g} grid points at {resolution} m", "the polygon"
    )
    X, Y = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel()] * resolution
    return pts[shapely.contains_xy(shapely.Polygon(polygon), pts[:, 0], pts[:, 1])]


def build_surface_map(
    robot: Robot,
    rmaps: dict[str, ReachabilityMap],
    polygon: ArrayLike | str,
    height: float,
    resolution: float = 0.05,
    orientations: int = 16,
    combine: str = "any",
    cone: float | None = math.pi / 4,
    tcp_height: float = TCP_HEIGHT,
) -> SurfaceMap:
    """The surface map of a polygon at ``height`` for one or more arms (seed 002 III-A, eq. 2).

    Args:
        robot: the robot (its footprint invalidates poses over the surface's furniture).
        rmaps: reachability map per arm name.
        polygon: the surface's outline, (N, 2) or ``"x1,y1;x2,y2;..."`` [m].
        height: surface height above the floor [m].
        resolution: grid spacing of surface points and base positions [m].
        orientations: base headings, evenly spaced.
        combine: "any" (max over arms) or "both" (min over arms).
        cone: approach cone about straight down [rad]; None counts any orientation.
        tcp_height: height of the TCP above the surface when it works there [m].

    Raises:
        InputError: a bad polygon, height, resolution, orientation count or combination, a map of
            another robot, a grid over the memory cap (:func:`check_surface_grid`), or a polygon
            with no grid point inside at this resolution.
    """
    pts = parse_polygon(polygon)
    if combine not in COMBINE:
        raise unknown("arm combination", combine, COMBINE)
    if not rmaps:
        raise InputError("no reachability map given")
    if not (math.isfinite(height) and 0.0 <= height <= 3.0):
        raise InputError(f"surface height must be between 0 and 3 m, got {height}")
    for name, rmap in rmaps.items():
        if rmap.info.robot != robot.name or rmap.info.arm != name:
            raise InputError(f"the map for arm {name!r} was built for {rmap.info.robot}/{rmap.info.arm}")
    check_surface_grid(pts, resolution, orientations, max(rmap.horizontal_reach for rmap in rmaps.values()))
    grid_pts = surface_grid(pts, resolution)
    if len(grid_pts) == 0:
        raise InputError(f"the polygon holds no grid point at resolution {resolution} m; use a finer one")
    thetas = np.arange(orientations, dtype=np.float64) * (2 * math.pi / orientations)
    g = np.rint(grid_pts / resolution).astype(np.int64)
    g0 = g.min(axis=0)
    mask = np.zeros(tuple(g.max(axis=0) - g0 + 1), dtype=np.float32)
    mask[g[:, 0] - g0[0], g[:, 1] - g0[1]] = 1.0
    # imported here: scipy.signal takes 1 s to import, and loading a surface map needs none of it
    from scipy.signal import fftconvolve

    combined: NDArray[np.float32] | None = None
    for name, rmap in rmaps.items():
        approach = robot.arm(name).approach_axis  # the arm's own, from its robot file
        pm, half = point_map(rmap, height + tcp_height, resolution, thetas, cone, approach)
        acc = np.stack([fftconvolve(mask, p, mode="full") for p in pm])
        acc = np.clip(acc / len(grid_pts), 0.0, 1.0).astype(np.float32)  # FFT round-off stays in [0, 1]
        acc[acc < 0.5 / len(grid_pts)] = 0.0  # below one point's share: FFT noise, not reach
        combined = acc if combined is None else COMBINE[combine](combined, acc)
    assert combined is not None
    origin = (float(g0[0] * resolution - half), float(g0[1] * resolution - half))
    combined *= _valid_poses(robot, pts, origin, resolution, combined.shape, thetas)
    return SurfaceMap(combined, origin, resolution, pts, float(height), robot.name, tuple(rmaps), combine, cone,
                      tcp_height)  # fmt: skip


def _valid_poses(
    robot: Robot,
    polygon: FloatArray,
    origin: tuple[float, float],
    resolution: float,
    shape: tuple[int, ...],
    thetas: FloatArray,
) -> NDArray[np.bool_]:
    """(T, NX, NY) poses whose footprint stays off the surface's footprint (its furniture).

    The polygon is rasterized conservatively (every cell it touches) and dilated by the rotated
    footprint kernel, which covers every cell within half a diagonal of the footprint.
    """
    _, nx, ny = shape
    img = np.zeros((ny * 8, nx * 8), dtype=np.uint8)  # rows: y, columns: x, at 1/8 cell
    px = ((polygon - np.asarray(origin)) / resolution + 0.5) * 8
    cv2.fillPoly(img, [np.rint(px).astype(np.int32)], 1)
    occupied = img.reshape(ny, 8, nx, 8).max(axis=(1, 3))
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    valid = np.empty((len(thetas), nx, ny), dtype=bool)
    for t, theta in enumerate(thetas):
        # cv2.dilate takes the max over the kernel's cells around each pose (a correlation), so a
        # pose is marked exactly when its footprint covers an occupied cell; both are indexed (y, x)
        kernel = footprint_kernel(outline, float(theta), resolution)
        valid[t] = (cv2.dilate(occupied, kernel) == 0).T
    return valid
