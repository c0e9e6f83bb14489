"""Sampling good, spread-out base poses from a surface map (seed 002, section III-B).

Random continuous candidates (x, y, yaw) are drawn in the map's bounding box and discarded, in
order of cost, when R_S = 0, when they lie outside the operational area (an occupancy grid: the
cell is free and the footprint keeps clear of occupied cells), or when the robot, at its
reference configuration, collides with the surface's furniture (a full collision check). Of N
valid candidates (default 40) the one with the highest discounted R_S wins. The discount of eq.
3, ``w = prod_i min(1, d(c, p_i))``, uses the normalized Euclidean distance d between the
candidate c and every earlier sample p_i over (x, y, z, yaw), with scales S = (0.5 m, 0.5 m,
0.5 m, pi/4): poses closer than that to an earlier one lose value, which spreads consecutive
samples around the surface (seed 002 Fig. 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely
from numpy.typing import NDArray

from baseplace.errors import InputError, NothingFoundError
from baseplace.geometry.poses import BasePose, FloatArray, wrap_angle
from baseplace.guards import check_alloc
from baseplace.placement.surface_map import SurfaceMap, surface_grid
from baseplace.robots.model import Robot
from baseplace.terrain.voxels import BYTES_PER_POINT, VoxelMap

if TYPE_CHECKING:
    from baseplace.world.environment import Environment
    from baseplace.world.occupancy import OccupancyGrid

DISCOUNT_SCALES = (0.5, 0.5, 0.5, math.pi / 4)
"""S of eq. 3: distances [m, m, m, rad] below which an earlier sample discounts a candidate."""
FREE_BELOW = 50
"""Occupancy values (0-100) below this are free; unknown (-1) is outside the operational area."""
BATCH = 256


@dataclass(frozen=True)
class SurfaceSample:
    """One base pose drawn around a surface, with what chose it.

    Attributes:
        pose: the base pose, yaw in (-pi, pi].
        reachability: R_S of the pose.
        score: R_S times the discount when it was chosen.
    """

    pose: BasePose
    reachability: float
    score: float


def discount(
    candidates: FloatArray, previous: FloatArray, scales: tuple[float, ...] = DISCOUNT_SCALES
) -> FloatArray:
    """Eq. 3: per candidate (N, 3) (x, y, yaw), the product over earlier poses (M, 3) of min(1, d).

    Poses stand on the floor (z = 0), so the z term of the distance vanishes.
    """
    c = np.asarray(candidates, dtype=float).reshape(-1, 3)
    p = np.asarray(previous, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.ones(len(c))
    dxy = (c[:, None, :2] - p[None, :, :2]) / np.asarray(scales[:2])
    dth = (np.angle(np.exp(1j * (c[:, None, 2] - p[None, :, 2])))) / scales[3]
    d = np.sqrt((dxy**2).sum(axis=-1) + dth**2)
    return np.prod(np.minimum(1.0, d), axis=1)


def furniture_voxels(smap: SurfaceMap, resolution: float = 0.025) -> VoxelMap:
    """The surface's furniture as a solid block of voxels from the floor to the surface height.

    Raises:
        InputError: the block (the polygon's cells times the layers up to the height) holds more
            voxels than the memory cap allows; checked before any is allocated.
    """
    outline = shapely.Polygon(smap.polygon).exterior
    n_edge = math.ceil(outline.length / (resolution / 2))
    z = np.arange(resolution / 2, max(smap.height, resolution), resolution)
    span = np.ceil(np.ptp(smap.polygon, axis=0) / resolution) + 2
    n_points = (float(np.prod(span)) + n_edge) * len(z)
    check_alloc(
        n_points * (24 + BYTES_PER_POINT), f"the furniture's {n_points:.3g} voxels", "the surface map"
    )
    xy = surface_grid(smap.polygon, resolution) + resolution / 2
    edge = np.array([outline.interpolate(s).coords[0] for s in np.arange(0, outline.length, resolution / 2)])
    xy = np.r_[xy, edge]
    pts = np.c_[np.repeat(xy, len(z), axis=0), np.tile(z, len(xy))]
    return VoxelMap.from_points(pts, resolution)


@dataclass
class SurfaceSampler:
    """Draws base poses from a surface map, spreading consecutive ones (seed 002 III-B).

    Args:
        smap: the surface map.
        robot: the robot, for the footprint and the full collision check (None: no collision check).
        occupancy: the operational area, or None for anywhere.
        candidates: N, valid candidates per sample (default 40).
        discounted: apply the eq. 3 discount (default True).
        max_draws: random draws per sample before giving up.
    """

    smap: SurfaceMap
    robot: Robot | None = None
    occupancy: OccupancyGrid | None = None
    candidates: int = 40
    discounted: bool = True
    max_draws: int = 20_000
    history: list[SurfaceSample] = field(default_factory=list)
    _environment: Environment | None = field(default=None, init=False, repr=False)
    _radius: float = field(default=0.0, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.candidates < 1:
            raise InputError(f"candidates must be >= 1, got {self.candidates}")
        if self.robot is not None:
            if self.robot.name != self.smap.robot:
                raise InputError(f"the surface map is for robot {self.smap.robot!r}, not {self.robot.name!r}")
            from baseplace.world.environment import Environment

            self._environment = Environment(self.robot, furniture_voxels(self.smap), self_collision=False)
            self._radius = self.robot.spec.footprint_bounding_radius
        if self.occupancy is not None:
            poses, _ = self.smap.cell_poses()
            if not self._in_area(poses[:, :2]).any():
                raise InputError(
                    f"the occupancy grid {self.occupancy.source or ''} leaves no free pose with R_S > 0 around "
                    "the surface; check that the map and the surface polygon share a frame"
                )

    def _in_area(self, xy: FloatArray) -> NDArray[np.bool_]:
        assert self.occupancy is not None
        v = self.occupancy.value_at(xy)
        return (v >= 0) & (v < FREE_BELOW) & (self.occupancy.clearance(xy) > self._radius)

    def _collides(self, pose: FloatArray) -> bool:
        if self._environment is None or self.robot is None:
            return False
        T = BasePose(float(pose[0]), float(pose[1]), float(pose[2])).matrix()
        return self._environment.colliding(self.robot.q_reference, T)

    def sample(self, rng: np.random.Generator) -> SurfaceSample:
        """The best of N valid candidates by discounted R_S; remembered for later discounts.

        Raises:
            NothingFoundError: no valid candidate within ``max_draws`` draws.
        """
        x0, y0, x1, y1 = self.smap.bounds
        valid: list[FloatArray] = []
        draws = 0
        while len(valid) < self.candidates and draws < self.max_draws:
            c = np.c_[
                rng.uniform(x0, x1, BATCH), rng.uniform(y0, y1, BATCH), rng.uniform(0, 2 * math.pi, BATCH)
            ]
            draws += BATCH
            c = c[self.smap.reachability(c) > 0]  # cheapest test first
            if self.occupancy is not None and len(c):
                c = c[self._in_area(c[:, :2])]
            for pose in c:
                if len(valid) == self.candidates:
                    break
                if not self._collides(pose):
                    valid.append(pose)
        if not valid:
            raise NothingFoundError(
                f"no valid pose in {draws} draws around the surface (R_S > 0, operational area, collision-free)"
            )
        cand = np.array(valid)
        rs = self.smap.reachability(cand).astype(float)
        w = (
            discount(cand, np.array([[p.pose.x, p.pose.y, p.pose.yaw] for p in self.history]))
            if self.discounted
            else 1.0
        )
        best = int(np.argmax(rs * w))
        score = float((rs * w if self.discounted else rs)[best])
        heading = float(wrap_angle(cand[best, 2]))  # (-pi, pi], as every base pose (navigate takes it)
        out = SurfaceSample(
            BasePose(float(cand[best, 0]), float(cand[best, 1]), heading), float(rs[best]), score
        )
        self.history.append(out)
        return out
