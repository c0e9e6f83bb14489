"""Placement generation end to end (seed 000, Algorithm 2).

cloud -> planar regions -> obstacle voxels (support removed) -> OSRM -> strategy candidates ->
verification (footprint, IK per target, collision, reaching motion) -> robustness to base error
-> at most M placements within N tries.

Only the hand may touch the grasped object (:mod:`baseplace.world.grasped_object`), given or found
at the first target's grasp point, and only in the reaching motion's final approach; the surface
under it and everything else are obstacles.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.placement import deadline
from baseplace.placement.motion import MotionChecker, MotionSettings, transit_environment
from baseplace.placement.osrm import OSRM, build_osrm, footprint_kernels
from baseplace.placement.robustness import RobustnessScorer, RobustnessSettings, rank_by_robustness
from baseplace.placement.scene_cache import Same, SceneCache, object_key
from baseplace.placement.strategies import make_strategy
from baseplace.placement.verify import Placement, Verifier
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.terrain.graph import GraphSettings
from baseplace.terrain.pipeline import Terrain, terrain_from_points
from baseplace.terrain.polygons import footprint_outline
from baseplace.terrain.segmentation import Segmentation
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.clearance import check_clearance
from baseplace.world.environment import (
    SUPPORT_DIST,
    Environment,
    contact_groups,
    obstacle_voxels,
    support_plane,
)
from baseplace.world.grasped_object import GraspedObject, find_grasped_object, rows_in
from baseplace.world.neighbour_shapes import FittedShape
from baseplace.world.obstacles import Obstacle, obstacles_key
from baseplace.world.sensor_resolution import (
    Group,
    derived_clearance,
    derived_plane_clearance,
    group_parts,
    object_obstacle,
    scene_noise,
    surface_noise,
)
from baseplace.world.support_plane import RADIUS

POSE_ONLY_CHECKS: dict[str, Any] = {"motion": None, "robustness": RobustnessSettings(samples=0)}
"""PlaceSettings overrides that check the placement's pose alone (IK + collision at the exact pose,
no reaching motion, no robustness score), as seed 000's experiments measure it:
``PlaceSettings(..., **POSE_ONLY_CHECKS)``."""


STAND_ON = ("ground", "any")
"""Where the base may stand (:attr:`PlaceSettings.stand_on`)."""


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
        resolution: height-map cell [m]; None: chosen from the cloud (terrain.diagnose.auto_resolution).
        motion: the reaching-motion check (:mod:`baseplace.placement.motion`), None: off.
        robustness: the score under base error and whether to rank by it or require a minimum
            (:mod:`baseplace.placement.robustness`).
        clearance: a link closer than this [m] to the scene at sensor resolution (the cloud's
            points near the grasped object, the plane it stands on) touches it; None: derived from
            the cloud, 3 sigma of its noise near the object in the worst direction
            (:func:`~baseplace.world.sensor_resolution.derived_clearance`).
        stand_on: where the base may stand. "ground" (default): the planar regions large enough
            for the footprint that the base can drive onto from the ground, the lowest of them,
            over traversable borders (:func:`ground_regions`); a table top with no ramp to it
            stays an obstacle. "any": every region large enough, as seed 000's experiments
            count placements (its Tables I and II).
    """

    strategy: str = "MR"
    placements: int = 1
    tries: int = 100
    n_orientations: int = 36
    gamma_max: float = math.pi / 4
    support_dist: float = SUPPORT_DIST
    resolution: float | None = None
    motion: MotionSettings | None = field(default_factory=MotionSettings)
    robustness: RobustnessSettings = field(default_factory=RobustnessSettings)
    clearance: float | None = None
    stand_on: str = "ground"

    def __post_init__(self) -> None:
        check_clearance(self.clearance)
        if self.stand_on not in STAND_ON:
            raise InputError(f"stand_on must be one of {', '.join(STAND_ON)}, got {self.stand_on!r}")
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
        timings_ms: segmentation, osrm (built, or found in the scene's cache), collision_setup (the grasped object and the obstacle
            OcTrees), query (candidates and verification), request_to_placement (all but the
            segmentation: seed 000's t_a) and total [ms]; the query's share spent in the
            reaching-motion check (motion) and the robustness score (robustness).
        terrain: the segmented scene.
        osrm: the OSRM.
        contacts: per (robot link, what it touched), the candidates rejected for it
            (see :class:`~baseplace.placement.verify.Verifier`).
        rejected: per rejected candidate, (x, y) [m], reason and first contact.
        grasped: the object only the hand may touch, or None.
        grasped_note: how it was found ("given", "auto: ..." or "none").
        clearance: the clearance [m] the checks kept (:attr:`PlaceSettings.clearance`).
        clearance_note: how it was chosen ("given", "3 sigma of ...", "default: ...").
        noise_margin: the derived noise margin n [m] (3 sigma of the scene's noise): the robot keeps
            ``clearance`` - n from the true surface (:func:`~baseplace.world.sensor_resolution.margin`).
        motion_failures: per reason the reaching-motion check gave
            (:data:`~baseplace.placement.motion.MOTION_FAILURES`), the candidates rejected for it.
    """

    placements: list[Placement]
    failures: Counter[str]
    tries: int
    timings_ms: dict[str, float]
    terrain: Terrain
    osrm: OSRM
    contacts: Counter[tuple[str, str]] = field(default_factory=Counter)
    rejected: list[tuple[tuple[float, float], str, tuple[str, str] | None]] = field(default_factory=list)
    grasped: GraspedObject | None = None
    grasped_note: str = "none"
    clearance: float = 0.0
    clearance_note: str = ""
    noise_margin: float = 0.0
    motion_failures: Counter[str] = field(default_factory=Counter)


def place(
    robot: Robot,
    rmap: ReachabilityMap,
    points: ArrayLike,
    targets: ArrayLike,
    settings: PlaceSettings | None = None,
    rng: np.random.Generator | None = None,
    terrain: Terrain | None = None,
    environments: dict[str, Environment] | None = None,
    grasped: GraspedObject | str | None = None,
    cache: SceneCache | None = None,
    obstacles: Sequence[Obstacle] = (),
) -> PlacementResult:
    """Find verified base placements from which the map's arm reaches every target.

    Args:
        robot: the robot (must match the map).
        rmap: reachability map of the arm to use.
        points: (N, 3) z-up world cloud of the scene [m].
        targets: (K, 4, 4) or (4, 4) world TCP targets.
        settings: search settings.
        rng: randomness (default: seed 0).
        terrain: the scene's segmentation to reuse (skips segmentation): of ``points``, or of
            another cloud of the same scene (seed 000 VI segments a noisy height map); the
            collision model is built from ``points`` either way.
        environments: a cache of collision environments for this terrain, filled on first use
            (repeated queries in one scene then skip building the obstacle OcTree); not used
            with a grasped object.
        grasped: the object the hand holds at the targets, which only the hand may touch: a
            :class:`GraspedObject`, "auto" (the cloud's cluster at the first target's grasp point,
            :func:`find_grasped_object`; none if no point is near it) or None (nothing may be
            touched).
        cache: what earlier queries in this scene built (segmentation, obstacle voxels, collision
            environments, per grasped object too, and the OSRM per targets), reused and filled
            (:class:`SceneCache`);
            ``points`` must be its cloud. Takes the place of ``terrain`` and ``environments``.
        obstacles: collision objects given by hand (:mod:`baseplace.world.obstacles`), checked
            beside the cloud's voxels by every check (collision, reaching motion, robustness).
    """
    s = settings or PlaceSettings()
    rng = rng or np.random.default_rng(0)
    T_targets = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    if not np.all(np.isfinite(T_targets)):
        raise InputError("target pose contains NaN or infinity")
    strategy = make_strategy(s.strategy, s.gamma_max)
    t0 = time.perf_counter()
    if cache is not None:
        terrain = terrain or cache.terrain(s.resolution)
    terrain = terrain or terrain_from_points(points, resolution=s.resolution)
    seg = terrain.segmentation
    t1 = time.perf_counter()
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    _check_targets(seg, T_targets)
    allowed = support_regions(terrain, s, outline, cache)

    def make_osrm() -> OSRM:
        made = build_osrm(seg, rmap, T_targets, outline, rmap.horizontal_reach, s.n_orientations, allowed)
        for array in (made.values, made.near, made.fits, made.gammas):
            array.flags.writeable = False  # shared by the scene's queries: read only
        return made

    t_osrm = time.perf_counter()
    if cache is None:
        osrm = make_osrm()
    else:  # per scene and targets: a query that asks again for the same targets finds it made
        osrm = cache.per_targets(("osrm", Same(rmap), Same(seg), T_targets.tobytes(), outline.tobytes(),
                                  s.n_orientations, None if allowed is None else tuple(allowed)), make_osrm)  # fmt: skip
    osrm_ms = (time.perf_counter() - t_osrm) * 1e3
    if not osrm.near.any():
        raise InputError(
            f"no planar region lies within the arm's reach ({rmap.horizontal_reach:.2f} m) of every target"
        )
    if not osrm.fits.any():
        size = robot.spec.footprint_bounding_radius
        if allowed is not None and len(allowed) < len(standable_regions(seg, outline)):
            raise InputError(
                f"no planar region within reach of the targets is large enough for the robot's footprint "
                f"(bounding radius {size:.2f} m) and joined to the ground by borders the base can drive "
                f"over (steps up to {GraphSettings().max_step} m; regions {sorted(allowed)}); "
                f"--stand-on any counts every region"
            )
        raise InputError(
            f"no planar region within reach of the targets is large enough for the robot's footprint "
            f"(bounding radius {size:.2f} m)"
        )
    t2 = time.perf_counter()
    checks = scene_checks(robot, rmap.info.arm, points, terrain, T_targets, s, grasped, cache, environments,
                          obstacles)  # fmt: skip
    verifier, motion, obj, note = checks.verifier, checks.verifier.motion, checks.grasped, checks.grasped_note
    rs = s.robustness
    scorer = RobustnessScorer(verifier.arm, verifier.environment, rs, motion) if rs.samples > 0 else None
    t3 = time.perf_counter()
    placements: list[Placement] = []
    tries = 0
    wanted = max(s.placements, rs.pool) if rs.rank == "robustness" else s.placements
    candidates = strategy.candidates(osrm, rmap, rng)
    robustness_s = scoring_motion_s = 0.0  # the motion checks of the score count as the score's
    while tries < s.tries and len(placements) < wanted:
        deadline.check()  # a service request past its time limit stops here
        candidate = next(candidates, None)
        if candidate is None:
            verifier.failures["exhausted"] += 1
            break
        tries += 1
        placement = verifier.check(candidate, rng)
        if placement is not None and scorer is not None:
            t, m = time.perf_counter(), motion.elapsed_s if motion is not None else 0.0
            placement = scorer.scored(placement)
            robustness_s += time.perf_counter() - t
            scoring_motion_s += (motion.elapsed_s if motion is not None else 0.0) - m
            if scorer.too_low(placement):
                verifier.failures["robustness"] += 1
                placement = None
        if placement is not None:
            placements.append(placement)
    if rs.rank == "robustness":
        placements = rank_by_robustness(placements)[: s.placements]
    t4 = time.perf_counter()
    timings = {
        "segmentation": (t1 - t0) * 1e3,
        "osrm": osrm_ms,
        "collision_setup": (t3 - t2) * 1e3,
        "query": (t4 - t3) * 1e3,
        "request_to_placement": (t4 - t1) * 1e3,
        "motion": (motion.elapsed_s - scoring_motion_s) * 1e3 if motion is not None else 0.0,
        "robustness": robustness_s * 1e3,
        "total": (t4 - t0) * 1e3,
    }
    return PlacementResult(placements, verifier.failures, tries, timings, terrain, osrm, verifier.contacts,
                           verifier.rejected, obj, note, checks.clearance, checks.clearance_note,
                           checks.noise_margin, verifier.motion_failures)  # fmt: skip


@dataclass
class SceneChecks:
    """The checks :func:`place` runs on every candidate, assembled once for a scene and its targets.

    Attributes:
        verifier: footprint, IK, collision and (with ``settings.motion``) reaching-motion checks.
        grasped: the object only the hand may touch, or None.
        grasped_note: how it was found ("given", "auto: ..." or "none").
        clearance: the clearance [m] kept from the scene at sensor resolution.
        clearance_note: how it was chosen (see :attr:`PlacementResult.clearance_note`).
        noise_margin: as :attr:`PlacementResult.noise_margin`.
    """

    verifier: Verifier
    grasped: GraspedObject | None
    grasped_note: str
    clearance: float = 0.0
    clearance_note: str = ""
    noise_margin: float = 0.0


def scene_checks(
    robot: Robot,
    arm_name: str,
    points: ArrayLike,
    terrain: Terrain,
    targets: FloatArray,
    settings: PlaceSettings,
    grasped: GraspedObject | str | None,
    cache: SceneCache | None = None,
    environments: dict[str, Environment] | None = None,
    obstacles: Sequence[Obstacle] = (),
) -> SceneChecks:
    """The verification of :func:`place` for one scene (cloud (N, 3), its terrain) and targets (K, 4, 4).

    The one assembly of the collision model (support, obstacles, grasped object), IK and reaching
    motion: :func:`place` checks its candidates with it, ``explain`` one given base pose.
    ``grasped``, ``cache``, ``environments`` and ``obstacles`` as in :func:`place`.
    """
    s = settings
    seg = terrain.segmentation
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    obj, note = _grasped_object(robot, arm_name, points, targets, grasped, cache)
    key = "floor" if s.strategy == "orm" else "regions"
    if cache is None:
        cache = SceneCache(points, terrain, s.resolution)  # this query only
    voxels = cache.shared(("obstacles", key, s.resolution, s.support_dist, s.stand_on, outline.tobytes()),
                          lambda: _obstacles(terrain, s, outline, cache))  # fmt: skip
    floor = _floor(cache, key, s, outline, terrain, voxels)
    transit = None
    clearance, clearance_note, noise_margin = NO_FINE_SCENE
    if obj is not None:  # the allowed contact: per grasped object, kept for the scene's next queries

        def environments_for_object() -> tuple[Environment, Environment | None, tuple[float, str, float]]:
            # near it the cloud's points and the exact plane it stands on, kept at the clearance
            groups, object_voxels = contact_groups(terrain.voxels, voxels, obj, cache.points, floor)
            kept = clearance_of(groups, s.clearance, cache.points, obj)
            plane, kept = plane_clearance_of(groups, s.clearance, kept)
            kept = fitted_noted(groups, kept, object_voxels)
            hand = Environment(robot, groups, grasped=object_voxels, hand_arm=arm_name, shapes=obstacles,
                               clearance=kept[0], plane_clearance=plane)  # fmt: skip
            # on the way to the pre-grasp the hand may not touch it either
            return hand, transit_environment(robot, groups, object_voxels, obstacles, kept[0], plane), kept

        env, transit, (clearance, clearance_note, noise_margin) = cache.per_object(
            ("environment", robot, arm_name, key, s.resolution, s.support_dist, object_key(obj),
             obstacles_key(obstacles), s.clearance),
            environments_for_object,
        )  # fmt: skip
    elif environments is not None:
        env_key = key + obstacles_key(obstacles)
        if env_key not in environments:
            environments[env_key] = Environment(robot, contact_groups(voxels, voxels, None, floor=floor)[0],
                                                shapes=obstacles)  # fmt: skip
        env = environments[env_key]
    else:
        env = scene_environment(robot, cache, s, obstacles)
    arm = robot.arm(arm_name)
    motion = None
    if s.motion is not None:  # only the final approach may touch the grasped object, with the hand
        if transit is None:  # no grasped object: nothing may be touched anywhere
            motion = MotionChecker(robot, arm, env, None, s.motion)
        else:
            motion = MotionChecker(robot, arm, transit, env, s.motion)
    verifier = Verifier(arm, DampedLeastSquaresIK(arm), env, targets,
                        {r.id: terrain.polygons[r.id] for r in seg.regions}, outline,
                        motion=motion)  # fmt: skip
    return SceneChecks(verifier, obj, note, clearance, clearance_note, noise_margin)


NO_FINE_SCENE = (0.0, "not used: no grasped object, the scene is 25 mm voxels", 0.0)
"""The clearance of a scene checked without a grasped object: nothing is at sensor resolution."""


def clearance_of(
    groups: dict[str, Group], given: float | None, points: ArrayLike, grasped: GraspedObject
) -> tuple[float, str, float]:
    """The clearance [m] for the groups of :func:`contact_groups`, how it was chosen, and the noise margin n [m].

    n is the derived clearance, whether a clearance is given or not. Derived from the noise of the cloud (N, 3)
    within :data:`~baseplace.world.support_plane.RADIUS` of the grasped object in its worst direction
    (measured once, by :func:`contact_groups`), and the support plane's residuals.
    """
    noise = scene_noise(groups)
    if noise is None:  # no denoised cells near the object kept it
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        noise = surface_noise(p[grasped.footprint_within(p[:, :2], RADIUS)])
    derived = derived_clearance(support_plane(groups), noise=noise)
    if given is not None:
        return float(given), "given", derived[0]
    return derived[0], derived[1], derived[0]


def plane_clearance_of(
    groups: dict[str, Group], given: float | None, kept: tuple[float, str, float]
) -> tuple[float | None, tuple[float, str, float]]:
    """The clearance [m] from the exact support plane (None: ``kept``'s), and ``kept`` with it noted.

    A given clearance holds for the plane too; a derived one is the plane's own
    (:func:`~baseplace.world.sensor_resolution.derived_plane_clearance`).
    """
    plane = support_plane(groups)
    if given is not None or plane is None:
        return None, kept
    metres, note = derived_plane_clearance(plane, scene_noise(groups))
    return metres, (kept[0], f"{kept[1]}; from {note}: {metres * 1e3:.1f} mm", kept[2])


def fitted_noted(
    groups: dict[str, Group], kept: tuple[float, str, float], grasped: Group | None = None
) -> tuple[float, str, float]:
    """``kept`` with the shapes fitted as whole shapes noted: each neighbour's kind and error u, and the object's.

    The robot keeps c - n + u from such a neighbour (:func:`~baseplace.world.sensor_resolution.margin`),
    and from the grasped object's shape in the transit (``grasped``, its group:
    :func:`~baseplace.world.sensor_resolution.object_obstacle`), so the JSON's clearance note
    states every u in use (:mod:`baseplace.world.neighbour_shapes`).
    """
    shapes = [
        part for group in groups.values() for part in group_parts(group) if isinstance(part, FittedShape)
    ]
    own = None if grasped is None else object_obstacle(grasped)
    note = kept[1]
    if shapes:
        each = ", ".join(f"{shape.kind} u {shape.error * 1e3:.1f} mm" for shape in shapes)
        note += f"; {len(shapes)} neighbours fitted as whole shapes, kept c - n + u: {each}"
    if isinstance(own, FittedShape):
        note += (
            f"; the grasped object fitted as a {own.kind} (u {own.error * 1e3:.1f} mm), "
            "kept c - n + u in the transit"
        )
    return kept[0], note, kept[2]


@dataclass
class ObjectChecks:
    """The checks of the seed-004 methods for one object, assembled once (see :func:`object_checks`).

    Attributes:
        environment: the whole robot against the cloud's voxels and the obstacles; only the hand
            may touch the grasped object.
        motion: the reaching-motion check, or None.
        clearance_note: how the environment's clearance was chosen (see
            :attr:`PlacementResult.clearance_note`).
        noise_margin: as :attr:`PlacementResult.noise_margin`.
    """

    environment: Environment
    motion: MotionChecker | None
    clearance_note: str = ""
    noise_margin: float = 0.0


def object_checks(
    robot: Robot,
    arm_name: str,
    hand_arm: str | None,
    points: FloatArray | None,
    grasped: GraspedObject | None,
    motion: MotionSettings | None,
    cache: SceneCache | None = None,
    obstacles: Sequence[Obstacle] = (),
    clearance: float | None = None,
) -> ObjectChecks:
    """The collision model and reaching-motion check around an object, for the seed-004 methods.

    Args:
        robot: the robot.
        arm_name: the arm that reaches (the map's).
        hand_arm: the arm whose hand may touch ``grasped`` (None: the robot's default).
        points: (N, 3) the scene cloud [m], or None (an occupancy grid alone: self-collision only).
        grasped: the object only the hand may touch, or None.
        motion: the reaching-motion check's settings, or None to skip it.
        cache: the scene's cache of ``points``: the voxels and, per grasped object, the
            environments are kept for its next queries.
        obstacles: collision objects given by hand.
        clearance: as :attr:`PlaceSettings.clearance` (None: derived).
    """
    check_clearance(clearance)

    def environments() -> tuple[Environment, dict[str, Group], Group | None, tuple[float, str, float]]:
        voxels = VoxelMap(0.025, np.zeros((0, 3), np.int64))
        if points is not None:
            voxels = VoxelMap.from_points(points) if cache is None else cache.shared(
                ("voxels", 0.025), lambda: VoxelMap.from_points(points))  # fmt: skip
        groups, object_voxels = contact_groups(voxels, voxels, grasped, points)
        kept = NO_FINE_SCENE
        if grasped is not None:
            kept = clearance_of(groups, clearance, np.zeros((0, 3)) if points is None else points, grasped)
        plane, kept = plane_clearance_of(groups, clearance, kept)
        kept = fitted_noted(groups, kept, object_voxels)
        environment = Environment(robot, groups, grasped=object_voxels, hand_arm=hand_arm, shapes=obstacles,
                                  clearance=kept[0], plane_clearance=plane)  # fmt: skip
        return environment, groups, object_voxels, kept

    if cache is None:
        environment, groups, object_voxels, kept = environments()
    else:  # per robot, arm and grasped object, kept for the scene's next queries
        environment, groups, object_voxels, kept = cache.per_object(
            ("candidates", robot, hand_arm, object_key(grasped), obstacles_key(obstacles), clearance),
            environments,
        )
    checker = None
    if motion is not None:  # the way to the pre-grasp must avoid the object too
        arm = robot.arm(arm_name)
        transit = transit_environment(
            robot, groups, object_voxels, obstacles, environment.clearance, environment.plane_clearance
        )
        checker = MotionChecker(robot, arm, environment if transit is None else transit,
                                None if transit is None else environment, motion)  # fmt: skip
    return ObjectChecks(environment, checker, kept[1], kept[2])


def scene_environment(
    robot: Robot, cache: SceneCache, settings: PlaceSettings | None = None, obstacles: Sequence[Obstacle] = ()
) -> Environment:
    """The collision environment of a scene without a grasped object, made once per cache (and obstacles).

    What :func:`place` uses when nothing may be touched; call it when a scene arrives so that
    its first query finds the obstacle OcTree built.
    """
    s = settings or PlaceSettings()
    terrain = cache.terrain(s.resolution)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    key = "floor" if s.strategy == "orm" else "regions"

    def environment() -> Environment:  # built once per cache: a warm query finds it made
        voxels = cache.shared(("obstacles", key, s.resolution, s.support_dist, s.stand_on, outline.tobytes()),
                              lambda: _obstacles(terrain, s, outline, cache))  # fmt: skip
        floor = _floor(cache, key, s, outline, terrain, voxels)
        return Environment(robot, contact_groups(voxels, voxels, None, floor=floor)[0], shapes=obstacles)

    env_key = ("environment", robot, key, s.resolution, s.support_dist, s.stand_on, outline.tobytes())
    if not obstacles:
        return cache.shared(env_key, environment)
    # per query's obstacles, like a grasped object: only the last few are kept (a service's scene lives long)
    return cache.per_object((*env_key, obstacles_key(obstacles)), environment)


def with_floor(points: ArrayLike, z: float, margin: float = 2.0, spacing: float = 0.02) -> FloatArray:
    """The cloud (N, 3) plus a floor plane at height ``z`` [m] under and ``margin`` [m] around it.

    For clouds that show no floor (a table scanned from above): the robot needs a surface to stand
    on. The floor's points lie on a ``spacing`` [m] grid over the cloud's xy extent.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    finite = p[np.all(np.isfinite(p), axis=1)]
    if len(finite) == 0:
        raise InputError("the cloud has no finite points")
    if not math.isfinite(z) or z > float(finite[:, 2].max()):
        raise InputError(
            f"the floor height must be finite and below the cloud's top ({finite[:, 2].max():.2f} m), got {z}"
        )
    lo, hi = finite[:, :2].min(axis=0) - margin, finite[:, :2].max(axis=0) + margin
    xs, ys = np.arange(lo[0], hi[0], spacing), np.arange(lo[1], hi[1], spacing)
    X, Y = np.meshgrid(xs, ys)
    return np.concatenate([p, np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]])


def _grasped_object(
    robot: Robot,
    arm_name: str,
    points: ArrayLike,
    targets: FloatArray,
    grasped: GraspedObject | str | None,
    cache: SceneCache | None = None,
) -> tuple[GraspedObject | None, str]:
    """The object only the hand may touch, and how it was found."""
    if grasped is None:
        return None, "none"
    if isinstance(grasped, GraspedObject):
        return grasped, "given"
    if grasped != "auto":
        raise InputError(f'grasped must be a GraspedObject, "auto" or None, got {grasped!r}')
    point = (targets[0] @ robot.T_tcp_grasp(arm_name))[:3, 3]  # the grasp point, ahead of the TCP
    found = find_grasped_object(points, point) if cache is None else cache.grasped_object(point)
    if found is None:
        return None, f"auto: no object at the grasp point {np.round(point, 3).tolist()}"
    return found, f"auto: {len(found.points)} points at the grasp point {np.round(point, 3).tolist()}"


def standable_regions(seg: Segmentation, outline: FloatArray, n_orientations: int = 8) -> list[int]:
    """Ids of the regions large enough for the footprint (F, 2) at one of ``n_orientations`` headings.

    Only these are support for the base; the voxels of the others (a table top, a tray bottom)
    stay obstacles for every link.
    """
    gammas = np.arange(n_orientations, dtype=np.float64) * (2 * math.pi / n_orientations)
    kernels = footprint_kernels(outline, gammas, seg.hmap.resolution)
    out = []
    for r in seg.regions:
        mask = (seg.labels == r.id).astype(np.uint8)
        if any(cv2.erode(mask, k, borderValue=0).any() for k in kernels):
            out.append(r.id)
    return out


def place_obstacles(terrain: Terrain, settings: PlaceSettings, outline: FloatArray) -> VoxelMap:
    """The obstacle voxels :func:`place` checks the robot against (support removed), for footprint (F, 2).

    For a caller that builds the same collision model outside a query (an experiment's own planner).
    """
    return _obstacles(terrain, settings, outline)


def ground_regions(terrain: Terrain, outline: FloatArray) -> list[int]:
    """Ids of the regions the base can drive onto from the ground: where a wheeled base may stand.

    The ground is the lowest of the regions large enough for the footprint (F, 2)
    (:func:`standable_regions`; by the height of its centroid), a robot starts on the floor, and
    every such region whose centroid lies within ``max_step`` of its plane (a floor that clutter
    splits into several regions). Another region counts when a path of traversable borders of the region graph
    (seed 000 V: height steps up to ``max_step``) joins it to the ground through regions large
    enough too: a ramp and the platform at its top, not a table top (no border the base can
    cross) nor a raised platform with a ledge all round.
    """
    import networkx as nx

    seg = terrain.segmentation
    big = standable_regions(seg, outline)
    if not big:
        return []
    regions = {r.id: r for r in seg.regions}
    lowest = regions[min(big, key=lambda i: float(regions[i].centroid[2]))]
    step = GraphSettings().max_step
    # the floor split by clutter into several regions is one level: each part within a step of
    # the lowest region's plane at its centroid is ground too
    level = [
        i
        for i in big
        if abs(float(regions[i].centroid[2] - lowest.height_at(regions[i].centroid[None, :2])[0])) <= step
    ]
    roads = nx.Graph()
    roads.add_nodes_from(big)
    roads.add_edges_from((a, b) for a, b, traversable in terrain.graph.edges(data="traversable")
                         if traversable and a in roads and b in roads)  # fmt: skip
    return sorted(set().union(*(nx.node_connected_component(roads, i) for i in level)))


def support_regions(
    terrain: Terrain, settings: PlaceSettings, outline: FloatArray, cache: SceneCache | None = None
) -> list[int] | None:
    """The regions the base may stand on under ``settings.stand_on`` (None: every region, "any")."""
    if settings.stand_on == "any":
        return None
    if cache is None:
        return ground_regions(terrain, outline)
    # keyed as the obstacle voxels are: the cache's terrain at this resolution (an id() of a terrain
    # could be a collected one's, reused)
    return cache.shared(
        ("ground regions", settings.resolution, outline.tobytes()), lambda: ground_regions(terrain, outline)
    )


def _obstacles(
    terrain: Terrain, s: PlaceSettings, outline: FloatArray, cache: SceneCache | None = None
) -> VoxelMap:
    seg = terrain.segmentation
    if s.strategy != "orm":
        allowed = support_regions(terrain, s, outline, cache)
        return obstacle_voxels(terrain.voxels, seg, s.support_dist,
                               standable_regions(seg, outline) if allowed is None else allowed)  # fmt: skip
    # The flat-floor baseline knows one support surface: the floor at z = 0. Ramps are obstacles.
    z = terrain.voxels.centres[:, 2]
    return terrain.voxels.without(np.abs(z) <= s.support_dist)


def _floor(
    cache: SceneCache, key: str, s: PlaceSettings, outline: FloatArray, terrain: Terrain, obstacles: VoxelMap
) -> VoxelMap:
    """The support voxels :func:`_obstacles` removed (the surfaces the base may stand on), kept per scene.

    Group :data:`~baseplace.world.environment.FLOOR`: the base and its wheels stand on them, the
    geometries the arms move must keep off them (dev seed 25005: a hand went through the true floor).
    """
    return cache.shared(
        ("floor", key, s.resolution, s.support_dist, s.stand_on, outline.tobytes()),
        lambda: terrain.voxels.without(rows_in(terrain.voxels.keys, obstacles.keys)),
    )


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
