"""The ``place`` job: verified base placements for TCP targets in a scanned scene (seed 000).

Composes :func:`baseplace.placement.pipeline.place` (a cloud) or
:func:`baseplace.placement.in_map.place_in_map` (an occupancy grid, optionally with clouds), and,
with a start pose, keeps only the placements the base can drive to (seed 000 V).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.jobs import inputs
from baseplace.jobs.report import NoResultError, PlaceReport, RobotRef, placement_row
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from pathlib import Path as FilePath

    from baseplace.navigation.path import Path
    from baseplace.placement.pipeline import PlaceSettings
    from baseplace.placement.scene_cache import SceneCache
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import OccupancyGrid


@dataclass
class PlaceJob:
    """The inputs of :func:`place_job`.

    Attributes:
        targets: TCP targets "x y z roll pitch yaw" [m, rad], world frame (text or 6 numbers each).
        grasp_points: instead of ``targets``: poses of the grasp point (between the fingertips, the
            arm spec's ``grasp_frame``), same format; each becomes the TCP target that puts the
            grasp frame there (TIAGo: 0.151 m back along the approach axis).
        robot: built-in name, robot file or a loaded Robot.
        arm: the arm (None: the robot's default arm, or the map's).
        cloud: the scene cloud (files, a recording or loaded points).
        occupancy: navigation map (map_server YAML or loaded grid) in the cloud's world frame.
        map: reachability map: loaded, a file, or None for the cached default map.
        settings: the search (strategy, M, N, motion check, robustness); None: defaults.
        seed: random seed.
        start: current base pose "x y yaw" [m, rad, any range]: keep placements reachable from it.
        planner: path planner with ``start``: rrt (OMPL RRTConnect) or regions.
        object: the grasped object spec (auto, none, box ..., cylinder ..., points FILE).
        floor: add a floor plane at this height [m] under a cloud that shows none.
        obstacles: collision objects given by hand, beside the cloud: "box X Y Z SX SY SZ [YAW]",
            "cylinder X Y Z RADIUS HEIGHT" [m, rad] or a mesh file (:mod:`baseplace.world.obstacles`).
        png: also plot the OSRM with the placements here.
        mcap: also write the result as an MCAP recording.
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: the
            segmentation, obstacle tree and collision environments kept between queries (the service).
        segmentation_cache: without ``cache``, read the cloud's segmentation from the per-user
            cache (:mod:`baseplace.terrain.cache`) and store it there once computed; the same
            result either way, a second run on the same cloud skips the segmentation.
    """

    targets: Sequence[str | Sequence[float]]
    robot: Robot | str = DEFAULT_ROBOT
    arm: str | None = None
    cloud: inputs.CloudInput = field(default_factory=inputs.CloudInput)
    occupancy: OccupancyGrid | str | None = None
    map: ReachabilityMap | str | None = None
    settings: PlaceSettings | None = None
    seed: int = 0
    start: str | Sequence[float] | None = None
    planner: str = "rrt"
    object: str = "auto"
    floor: float | None = None
    png: str | None = None
    mcap: str | None = None
    cache: SceneCache | None = field(default=None, repr=False, compare=False)
    segmentation_cache: bool = field(default=True, compare=False)
    grasp_points: Sequence[str | Sequence[float]] = ()
    obstacles: Sequence[str] = ()

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        s = self.settings
        return {
            "robot": self.robot if isinstance(self.robot, str) else self.robot.name, "arm": self.arm,
            **self.cloud.echo(), "occupancy": self.occupancy if isinstance(self.occupancy, str | None) else "grid",
            "targets": [t if isinstance(t, str) else [float(v) for v in t] for t in self.targets],
            "map": self.map if isinstance(self.map, str | None) else "loaded", "seed": self.seed,
            "strategy": None if s is None else s.strategy, "placements": None if s is None else s.placements,
            "tries": None if s is None else s.tries, "start": self.start, "planner": self.planner,
            "object": self.object, "floor": self.floor,
            "grasp_points": [t if isinstance(t, str) else [float(v) for v in t] for t in self.grasp_points],
            "obstacles": list(self.obstacles),
        }  # fmt: skip

    def check_inputs(self) -> tuple[FilePath | None, FilePath | None, np.ndarray, np.ndarray | None]:
        """The inputs that need no library beyond numpy, checked before any work; parsed.

        The planner, the outputs (PNG, MCAP, the fused cloud's), the targets (or grasp points), the
        start pose and, last, the cloud files' names. Front ends call it before they build the settings,
        whose imports take seconds, so that a mistyped argument is refused at once.

        Returns:
            The PNG and MCAP paths (None: not asked), the targets (T, 4, 4) as given (TCP or grasp
            point poses) and the start "x y yaw" (3,) or None.
        """
        if self.planner not in ("rrt", "regions"):
            raise InputError(f"unknown planner {self.planner!r}; valid: regions, rrt")
        inputs.out_path(self.cloud.fused_out, "--fused-out", (".bt",))
        png = inputs.out_path(self.png, "--out", inputs.PLOT_SUFFIXES)
        mcap = inputs.out_path(self.mcap, "--mcap", (".mcap",))
        if self.targets and self.grasp_points:
            raise InputError(inputs.TARGET_AND_GRASP_POINT)
        if not self.targets and not self.grasp_points:
            raise InputError('give at least one --target "x y z roll pitch yaw" (the TCP pose) '
                             'or --grasp-point "x y z roll pitch yaw" (the point between the fingertips)')  # fmt: skip
        option, given = (
            ("--grasp-point", self.grasp_points) if self.grasp_points else ("--target", self.targets)
        )
        targets = np.stack(
            [
                inputs.target_pose(t, option if len(given) == 1 else f"{option} {k}")
                for k, t in enumerate(given)
            ]
        )
        inputs.check_object_yaw(self.object, "--object")
        start = None if self.start is None else inputs.base_xyyaw(self.start, "--start")
        inputs.check_robot_name(self.robot, self.arm)
        inputs.check_map_file(self.map)
        self.cloud.check_paths()  # the files last: a mistyped option is named first
        return png, mcap, targets, start


def pose_text(T: np.ndarray) -> str:
    """A (4, 4) pose as "x y z roll pitch yaw" [m, rad], to 0.1 mm and 1e-4 rad."""
    from baseplace.geometry.poses import matrix_to_rpy

    return " ".join(f"{v:.4f}" for v in (*T[:3, 3], *matrix_to_rpy(T[:3, :3])))


def _check_scene(
    job: PlaceJob,
    robot: Robot,
    targets: np.ndarray,
    start: np.ndarray | None,
    points: np.ndarray | None,
    grid: OccupancyGrid | None,
    resolution: float | None,
) -> None:
    """Refuse targets no support of the scene brings within the arm's reach, and a start off the scene.

    The scene's supports lie within the bounds of the cloud (and of the occupancy grid, floor at
    z = 0); the arm's reach is :class:`~baseplace.jobs.inputs.ReachBound`'s, from the robot model alone.
    """
    cache = job.cache if job.floor is None else None  # with a floor added here the points are not its cloud
    boxes = []
    if points is not None:  # a scene's cache found its cloud's bounds once
        boxes.append(cache.bounds if cache is not None else inputs.points_bounds(points))
    if grid is not None:
        boxes.append(inputs.grid_bounds(grid))
    bounds = (np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0))
    scene = {1: "the cloud's bounds", 2: "the occupancy grid's bounds"}.get(
        (points is not None) + 2 * (grid is not None), "the bounds of the cloud and the occupancy grid"
    )
    arm = job.arm
    if arm is None and not isinstance(job.map, str):  # else the map file's arm, not read yet: every arm
        arm = robot.spec.default_arm if job.map is None else job.map.info.arm
    labels = [f"target {k}" for k in range(len(targets))]
    inputs.check_in_reach(
        targets[:, :3, 3], labels, bounds, scene, inputs.ReachBound.of_robot(robot, arm), robot.name
    )
    if start is not None:
        inputs.check_on_scene(
            start, "--start", bounds, scene, inputs.CHECK_MARGIN + max(resolution or 0.0, 0.05)
        )


def place_job(job: PlaceJob, progress: inputs.Progress | None = None) -> PlaceReport:
    """Verified base placements for ``job.targets``.

    Raises:
        InputError: bad input (no targets, no scene, a start pose off the floor, an unwritable output).
        NoResultError: no verified placement, or none the base can drive to; ``report`` holds the
            failure counts and the contacts.
    """
    png, mcap, targets, start = job.check_inputs()  # first: before the imports and any work
    from baseplace.placement.pipeline import PlaceSettings, place, with_floor
    from baseplace.placement.verify import contact_summary, most_frequent_contact, motion_failure_summary
    from baseplace.reachability.cache import resolve_map
    from baseplace.world.grasped_object import parse_grasped_object
    from baseplace.world.obstacles import check_clear_of, parse_obstacles
    from baseplace.world.sensor_resolution import clearance_record

    t0 = time.perf_counter()
    grasped = parse_grasped_object(job.object)
    obstacles = parse_obstacles(job.obstacles)
    settings = job.settings or PlaceSettings()
    robot = inputs.load_robot(job.robot)
    if job.grasp_points:  # T_world_tcp = T_world_grasp T_grasp_tcp
        targets = targets @ np.linalg.inv(robot.T_tcp_grasp(job.arm))
    if obstacles:  # an obstacle at a grasp point blocks it from every base pose: say so now
        grasp_points = (targets @ robot.T_tcp_grasp(job.arm))[:, :3, 3]
        check_clear_of(obstacles, grasp_points, [f"target {k}" for k in range(len(targets))])
    cloud = inputs.world_cloud(job.cloud) if job.cloud.given else None
    grid = inputs.occupancy_grid(job.occupancy, job.cloud.bag, job.cloud)
    if cloud is None and grid is None:
        raise InputError(
            "give --cloud FILE, --occupancy MAP.yaml, or --bag FILE with --cloud-topic/--map-topic"
        )
    points = None
    if cloud is not None:
        points = cloud.points if job.floor is None else with_floor(cloud.points, job.floor)
    _check_scene(
        job, robot, targets, start, points, grid, settings.resolution
    )  # before the map and segmentation
    t_load = time.perf_counter()
    chosen = resolve_map(robot, job.map, job.arm, progress)
    rmap = chosen.rmap
    t_map = time.perf_counter()
    terrain = navmap = None
    if grid is None and job.cache is None and job.segmentation_cache:
        from baseplace.terrain.cache import cached_terrain

        assert points is not None  # a cloud or a grid was given
        t_seg = time.perf_counter()
        terrain = cached_terrain(points, resolution=settings.resolution)
        terrain.timings_ms["job"] = (time.perf_counter() - t_seg) * 1e3
    if start is not None and grid is None:
        from baseplace.navigation.navmap import navigation_map
        from baseplace.terrain.pipeline import terrain_from_points

        assert points is not None  # a cloud or a grid was given
        if terrain is None and job.cache is not None:  # the scene's segmentation, kept: no time of this query
            navmap = navigation_map(
                job.cache.terrain(settings.resolution), robot.spec.footprint_bounding_radius
            )
        else:
            terrain = terrain or terrain_from_points(points, resolution=settings.resolution)
            navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
        navmap.check_pose("--start", start[:2])
    rng = np.random.default_rng(job.seed)
    if grid is not None:
        from baseplace.placement.in_map import place_in_map

        result = place_in_map(robot, rmap, [] if points is None else [points], grid, targets, settings, rng,
                              grasped=grasped, obstacles=obstacles)  # fmt: skip
    else:
        assert points is not None
        result = place(robot, rmap, points, targets, settings, rng, terrain=terrain, grasped=grasped,
                       cache=job.cache, obstacles=obstacles)  # fmt: skip
    t_nav = time.perf_counter()
    reached = None
    if start is not None:  # on the navigation map, around what the cameras see; or on the scene's
        from baseplace.placement.drivable import drivable, grid_route, map_route

        if grid is not None:
            route = grid_route(grid, [] if cloud is None else [cloud.points], start,
                               robot.spec.footprint_bounding_radius)  # fmt: skip
        else:
            assert navmap is not None  # built above for a start on a cloud
            route = map_route(navmap, start, job.planner, job.seed)
        reached = drivable(result.placements, route)
        if grid is not None or reached.unreachable:  # as before: the grid's count shows even when 0
            result.failures["no_path"] += reached.unreachable
    kept = result.placements if reached is None else reached.placements
    routes: list[Path | None] = [None] * len(kept) if reached is None else list(reached.paths)
    rows = [placement_row(p, path=route) for p, route in zip(kept, routes, strict=True)]
    timings = {"load": (t_load - t0) * 1e3, **inputs.map_timing(chosen, t_map - t_load), **result.timings_ms}
    timings.pop("total", None)
    if terrain is not None:  # computed here (read from the cache, or segmented and stored): its time here
        timings["segmentation"] = terrain.timings_ms.get("job", terrain.timings_ms["total"])
        if "cache_read" in terrain.timings_ms:
            timings["segmentation_cache_read"] = terrain.timings_ms["cache_read"]
    if start is not None:
        timings["navigation"] = (time.perf_counter() - t_nav) * 1e3
    report = PlaceReport(
        robot=RobotRef.of(robot, rmap.info.arm), inputs=job.echo(), failures=dict(result.failures),
        targets=[t if isinstance(t, str) else " ".join(f"{float(v):g}" for v in t) for t in job.targets]
        or [pose_text(T) for T in targets],
        strategy=settings.strategy, seed=job.seed, placements=rows, tries=result.tries,
        collisions=contact_summary(result.contacts),
        object={"requested": job.object, "found": result.grasped_note,
                "allowed": None if result.grasped is None else result.grasped.to_json()},
        floor=job.floor, regions=len(result.terrain.segmentation.regions),
        clearance=clearance_record(result.clearance, result.clearance_note, result.noise_margin),
        motion_failures=dict(result.motion_failures),
    )  # fmt: skip
    report.outputs.update(inputs.map_output(chosen))
    if png is not None:
        from baseplace.terrain.polygons import footprint_outline
        from baseplace.viz.placement import plot_placement

        outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
        plot_placement(result.osrm, kept, outline, png,
                       f"{robot.name}, {settings.strategy}: {len(rows)} placement(s) in {result.tries} tries",
                       [r.poses for r in routes if r is not None], result.rejected, result.contacts,
                       result.grasped)  # fmt: skip
        report.outputs["png"] = str(png)
    if mcap is not None:
        T_kept = [p.T_world_base for p in kept]
        world = job.cloud.bag.world_frame if job.cloud.bag is not None else "map"
        inputs.write_mcap(mcap, world, inputs.bag_stamp(job.cloud), result.terrain, placements=T_kept, candidates=T_kept,
                   paths=[r.poses for r in routes if r is not None], targets=list(targets))  # fmt: skip
        report.outputs["mcap"] = str(mcap)
    report.timings_ms = {**timings, "total": (time.perf_counter() - t0) * 1e3}
    if not rows and result.placements:
        raise NoResultError(
            f"none of the {len(result.placements)} verified placement(s) can be driven to from --start "
            f"{job.start} ({job.planner} planner); ask for more with --placements",
            report,
        )
    if not rows:
        phrases = [(result.failures["collision"], most_frequent_contact(result.contacts)),
                   (result.failures["motion"], motion_failure_summary(result.motion_failures))]  # fmt: skip
        why = "".join(
            f"; {phrase}" for _, phrase in sorted(phrases, key=lambda p: -p[0]) if phrase
        )  # the more frequent first
        raise NoResultError(
            f"no verified placement in {result.tries} tries with {settings.strategy} "
            f"(failures: {dict(result.failures) or 'none'}{why}); "
            f"try --tries, another --strategy, --object or check the target",
            report,
        )
    return report
