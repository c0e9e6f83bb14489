"""Placement generation end to end (seed 000, Algorithm 2).

cloud -> planar regions -> obstacle voxels (support removed) -> OSRM -> strategy candidates ->
verification (footprint, IK per target, collision, reaching motion) -> robustness to base error
-> at most M placements within N tries.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.placement.osrm import OSRM, build_osrm
from baseplace.placement.robustness import RobustnessEstimator, RobustnessSettings, rank_by_robustness
from baseplace.placement.strategies import make_strategy
from baseplace.placement.verify import Placement, Verifier
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.terrain.pipeline import Terrain, terrain_from_points
from baseplace.terrain.polygons import footprint_outline
from baseplace.terrain.segmentation import Segmentation
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import SUPPORT_DIST, Environment, obstacle_voxels

SEED_000_CHECKS: dict[str, Any] = {"motion": None, "robustness": RobustnessSettings(samples=0)}
"""PlaceSettings overrides for seed 000's verification alone (IK + collision at the exact pose),
as its experiments measure it: ``PlaceSettings(..., **SEED_000_CHECKS)``."""


@dataclass(frozen=True)
class PlaceSettings:
    """How to search for placements.

    Attributes:
        strategy: MR, TO, MRTO (seed 000) or the baselines orm, grid, random.
        placements: M, stop after this many verified placements.
        tries: N, stop after this many candidates.
        n_orientations: l, OSRM orientations per cell (seed 000: 36).
        gamma_max: largest angle between the base's forward axis and the targets [rad].
        support_dist: voxels this close to their region's plane are support, not obstacles [m].
        resolution: height-map cell [m].
        motion: the reaching-motion check (:mod:`baseplace.placement.motion`), None: off.
        robustness: the score under base error and whether to rank by it or require a minimum
            (:mod:`baseplace.placement.robustness`).
    """

    strategy: str = "MR"
    placements: int = 1
    tries: int = 100
    n_orientations: int = 36
    gamma_max: float = math.pi / 4
    support_dist: float = SUPPORT_DIST
    resolution: float = 0.05
    motion: MotionSettings | None = field(default_factory=MotionSettings)
    robustness: RobustnessSettings = field(default_factory=RobustnessSettings)

    def __post_init__(self) -> None:
        if self.placements < 1 or self.tries < 1:
            raise InputError(f"placements and tries must be >= 1, got {self.placements} and {self.tries}")
        if not (0 < self.gamma_max <= math.pi):
            raise InputError(f"gamma_max must be in (0, pi], got {self.gamma_max}")


@dataclass
class PlacementResult:
    """What a placement query found.

    Attributes:
        placements: verified placements (at most M).
        failures: counts of rejected candidates by reason, and "exhausted" when the strategy ran dry.
        tries: candidates checked.
        timings_ms: segmentation, osrm, query and total [ms]; the query's share spent in the
            reaching-motion check (motion) and the robustness score (robustness).
        terrain: the segmented scene.
        osrm: the OSRM.
    """

    placements: list[Placement]
    failures: Counter[str]
    tries: int
    timings_ms: dict[str, float]
    terrain: Terrain
    osrm: OSRM


def place(
    robot: Robot,
    rmap: ReachabilityMap,
    points: ArrayLike,
    targets: ArrayLike,
    settings: PlaceSettings | None = None,
    rng: np.random.Generator | None = None,
    terrain: Terrain | None = None,
    environments: dict[str, Environment] | None = None,
    ignore: list[tuple[FloatArray, float]] | None = None,
) -> PlacementResult:
    """Find verified base placements from which the map's arm reaches every target.

    Args:
        robot: the robot (must match the map).
        rmap: reachability map of the arm to use.
        points: (N, 3) z-up world cloud of the scene [m].
        targets: (K, 4, 4) or (4, 4) world TCP targets.
        settings: search settings.
        rng: randomness (default: seed 0).
        terrain: a segmentation of the same cloud to reuse (skips segmentation).
        environments: a cache of collision environments for this terrain, filled on first use
            (repeated queries in one scene then skip building the obstacle OcTree).
        ignore: spheres (centre (3,), radius [m]) whose obstacle voxels the robot may touch: the
            object being grasped, which the closing hand surrounds (an allowed collision).
    """
    s = settings or PlaceSettings()
    rng = rng or np.random.default_rng(0)
    T_targets = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    if not np.all(np.isfinite(T_targets)):
        raise InputError("target pose contains NaN or infinity")
    strategy = make_strategy(s.strategy, s.gamma_max)
    t0 = time.perf_counter()
    terrain = terrain or terrain_from_points(points, resolution=s.resolution)
    seg = terrain.segmentation
    t1 = time.perf_counter()
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    _check_targets(seg, T_targets)
    osrm = build_osrm(seg, rmap, T_targets, outline, rmap.horizontal_reach, s.n_orientations)
    if not osrm.near.any():
        raise InputError(
            f"no planar region lies within the arm's reach ({rmap.horizontal_reach:.2f} m) of every target"
        )
    if not osrm.fits.any():
        size = robot.spec.footprint_bounding_radius
        raise InputError(
            f"no planar region within reach of the targets is large enough for the robot's footprint "
            f"(bounding radius {size:.2f} m)"
        )
    t2 = time.perf_counter()
    key = "floor" if s.strategy == "orm" else "regions"
    if ignore:  # obstacles depend on the grasped object: no reuse across queries
        obstacles = _obstacles(terrain, seg, s)
        centres = obstacles.centres
        allowed = np.zeros(len(centres), dtype=bool)
        for centre, radius in ignore:
            allowed |= np.linalg.norm(centres - np.asarray(centre, dtype=float), axis=1) <= radius
        env = Environment(robot, obstacles.without(allowed))
    else:
        cache = environments if environments is not None else {}
        if key not in cache:
            cache[key] = Environment(robot, _obstacles(terrain, seg, s))
        env = cache[key]
    arm = robot.arm(rmap.info.arm)
    motion = None
    if s.motion is not None:  # the path to the pre-grasp must also avoid the grasped object
        full = (
            env
            if not ignore
            else (environments or {}).get(key) or Environment(robot, _obstacles(terrain, seg, s))
        )
        motion = MotionChecker(robot, arm, full, env if ignore else None, s.motion)
    verifier = Verifier(arm, DampedLeastSquaresIK(arm), env, T_targets,
                        {r.id: terrain.graph.nodes[r.id]["polygon"] for r in seg.regions}, outline,
                        motion=motion)  # fmt: skip
    rs = s.robustness
    estimator = RobustnessEstimator(arm, env, T_targets, rs) if rs.samples > 0 else None
    t3 = time.perf_counter()
    placements: list[Placement] = []
    tries = 0
    wanted = max(s.placements, rs.pool) if rs.rank == "robustness" else s.placements
    candidates = strategy.candidates(osrm, rmap, rng)
    robustness_s = 0.0
    while tries < s.tries and len(placements) < wanted:
        candidate = next(candidates, None)
        if candidate is None:
            verifier.failures["exhausted"] += 1
            break
        tries += 1
        placement = verifier.check(candidate, rng)
        if placement is not None and estimator is not None:
            t = time.perf_counter()
            placement = estimator.scored(placement)
            robustness_s += time.perf_counter() - t
            if placement.robustness is not None and placement.robustness.rate < rs.minimum:
                verifier.failures["robustness"] += 1
                placement = None
        if placement is not None:
            placements.append(placement)
    if rs.rank == "robustness":
        placements = rank_by_robustness(placements)[: s.placements]
    t4 = time.perf_counter()
    timings = {
        "segmentation": (t1 - t0) * 1e3,
        "osrm": osrm.build_ms,
        "collision_setup": (t3 - t2) * 1e3,
        "query": (t4 - t3) * 1e3,
        "motion": motion.elapsed_s * 1e3 if motion is not None else 0.0,
        "robustness": robustness_s * 1e3,
        "total": (t4 - t0) * 1e3,
    }
    return PlacementResult(placements, verifier.failures, tries, timings, terrain, osrm)


def _obstacles(terrain: Terrain, seg: Segmentation, s: PlaceSettings) -> VoxelMap:
    if s.strategy != "orm":
        return obstacle_voxels(terrain.voxels, seg, s.support_dist)
    # The flat-floor baseline knows one support surface: the floor at z = 0. Ramps are obstacles.
    z = terrain.voxels.centres[:, 2]
    return terrain.voxels.without(np.abs(z) <= s.support_dist)


def _check_targets(seg: Segmentation, targets: FloatArray) -> None:
    """A target below the surface of the region under it lies inside an obstacle: say so."""
    row, col, inside = seg.hmap.cell_of(targets[:, :2, 3])
    for k, T in enumerate(targets):
        if not inside[k]:
            continue
        label = seg.labels[row[k], col[k]]  # labelled cells always have data
        if label >= 0:
            region = seg.regions[int(label)]
            below = float(region.height_at(T[None, :2, 3])[0])
            if T[2, 3] < below - 0.05:
                raise InputError(
                    f"target {k} at z = {T[2, 3]:.2f} m lies {below - T[2, 3]:.2f} m below the surface "
                    f"of region {region.id}: inside an obstacle"
                )
