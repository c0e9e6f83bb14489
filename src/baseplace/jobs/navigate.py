"""The ``navigate`` and ``segment`` jobs: a scanned scene's planar regions and a base path across them.

Segmentation is seed 000 IV (planar regions, polygons, region graph); the path is seed 000 V
(OMPL RRTConnect or the region-graph planner on the navigation map).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose
from baseplace.jobs.inputs import (
    CHECK_MARGIN,
    PLOT_SUFFIXES,
    CloudInput,
    bag_stamp,
    base_xyyaw,
    check_on_scene,
    check_robot_name,
    load_robot,
    out_path,
    points_bounds,
    world_cloud,
    write_mcap,
)
from baseplace.jobs.report import NavigateReport, RobotRef, SegmentReport, path_json
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.placement.scene_cache import SceneCache
    from baseplace.robots.model import Robot


@dataclass
class NavigateJob:
    """The inputs of :func:`navigate_job`.

    Attributes:
        start, goal: base poses "x y yaw" [m, rad]; headings within +-2 pi (wrapped to (-pi, pi]).
        cloud: the scene cloud.
        robot: built-in name, robot file or loaded Robot (its footprint radius).
        planner: rrt (OMPL RRTConnect) or regions (the region graph).
        time_limit: RRT planning time limit [s].
        resolution: height-map cell [m] (None: from the cloud).
        seed: random seed.
        png, mcap: also write a plot / an MCAP recording here.
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: its
            segmentation and bounds, made once (the service).
        segmentation_cache: without ``cache``, read the cloud's segmentation from the per-user
            cache (:mod:`baseplace.terrain.cache`) and store it there once computed, as ``place``.
    """

    start: str | Sequence[float]
    goal: str | Sequence[float]
    cloud: CloudInput = field(default_factory=CloudInput)
    robot: Robot | str = DEFAULT_ROBOT
    planner: str = "rrt"
    time_limit: float = 2.0
    resolution: float | None = None
    seed: int = 0
    png: str | None = None
    mcap: str | None = None
    cache: SceneCache | None = field(default=None, repr=False, compare=False)
    segmentation_cache: bool = field(default=True, compare=False)

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {"start": self.start if isinstance(self.start, str) else list(self.start),
                "goal": self.goal if isinstance(self.goal, str) else list(self.goal), **self.cloud.echo(),
                "robot": self.robot if isinstance(self.robot, str) else self.robot.name, "planner": self.planner,
                "time_limit": self.time_limit, "resolution": self.resolution, "seed": self.seed}  # fmt: skip


def navigate_job(job: NavigateJob) -> NavigateReport:
    """A base path from ``job.start`` to ``job.goal`` across the scene's planar regions.

    Raises:
        InputError: bad input (a pose off the floor, an unknown planner, an unwritable output).
        NothingFoundError: no path within the time limit.
    """
    if job.planner not in ("rrt", "regions"):
        raise InputError(f"unknown planner {job.planner!r}; valid: regions, rrt")
    png = out_path(job.png, "--out", PLOT_SUFFIXES)  # outputs first: before the imports and any work
    mcap = out_path(job.mcap, "--mcap", (".mcap",))
    start, goal = base_xyyaw(job.start, "--start"), base_xyyaw(job.goal, "--goal")
    job.cloud.check_given()
    check_robot_name(job.robot)
    job.cloud.check_paths()
    from baseplace.navigation.navmap import navigation_map
    from baseplace.navigation.planners import plan_path
    from baseplace.terrain.pipeline import terrain_from_points

    t0 = time.perf_counter()
    robot = load_robot(job.robot)
    cloud = world_cloud(job.cloud)
    # poses off the scene: refused before the segmentation (a scene's cache found its bounds on upload)
    bounds = job.cache.bounds if job.cache is not None else points_bounds(cloud.points)
    for what, pose in (("--start", start), ("--goal", goal)):
        check_on_scene(
            pose, what, bounds, "the cloud's bounds", CHECK_MARGIN + max(job.resolution or 0.0, 0.05)
        )
    t_load = time.perf_counter()
    if job.cache is not None:
        terrain = job.cache.terrain(job.resolution)
    elif job.segmentation_cache:
        from baseplace.terrain.cache import cached_terrain

        terrain = cached_terrain(cloud.points, resolution=job.resolution)
    else:
        terrain = terrain_from_points(cloud.points, resolution=job.resolution)
    navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
    path = plan_path(navmap, start, goal, job.planner, job.time_limit, job.seed)
    report = NavigateReport(
        robot=RobotRef.of(robot), inputs=job.echo(), planner=path.planner,
        start=BasePose.from_xyyaw(*start), goal=BasePose.from_xyyaw(*goal), poses=path_json(path.poses),
        length=round(path.length, 3), regions=[int(r) for r in path.regions], footprint_radius=navmap.radius,
    )  # fmt: skip
    if png is not None:
        from baseplace.viz.navigation import plot_navigation

        plot_navigation(navmap, [path], start, goal, png)
        report.outputs["png"] = str(png)
    if mcap is not None:
        world = job.cloud.bag.world_frame if job.cloud.bag is not None else "map"
        write_mcap(mcap, world, bag_stamp(job.cloud), terrain, paths=[path.poses])
        report.outputs["mcap"] = str(mcap)
    report.timings_ms = {"load": (t_load - t0) * 1e3, **{f"segmentation_{k}": v for k, v in terrain.timings_ms.items()},
                         "path": path.time_ms, "total": (time.perf_counter() - t0) * 1e3}  # fmt: skip
    return report


@dataclass
class SegmentJob:
    """The inputs of :func:`segment_job`.

    Attributes:
        cloud: the point cloud.
        algorithm: robust (seed 000) or baseline region growing.
        resolution: height-map cell [m] (None: from the cloud).
        png: also plot the regions here.
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: its robust
            segmentation, made once (the service).
    """

    cloud: CloudInput = field(default_factory=CloudInput)
    algorithm: str = "robust"
    resolution: float | None = None
    png: str | None = None
    cache: SceneCache | None = field(default=None, repr=False, compare=False)

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {**self.cloud.echo(), "algorithm": self.algorithm, "resolution": self.resolution}


def segment_job(job: SegmentJob) -> SegmentReport:
    """Planar regions, their polygons and the region graph of a cloud.

    Raises:
        InputError: bad input (an unreadable cloud, an unknown algorithm, an unwritable output).
    """
    if job.algorithm not in ("robust", "baseline"):
        raise InputError(f"unknown algorithm {job.algorithm!r}; valid: baseline, robust")
    png = out_path(job.png, "--out", PLOT_SUFFIXES)  # outputs first: before the imports and any work
    t0 = time.perf_counter()
    cloud = world_cloud(job.cloud)  # a bad cloud is refused before the segmentation is imported
    t_load = time.perf_counter()
    from baseplace.terrain.pipeline import terrain_from_points, terrain_json

    if job.cache is not None and job.algorithm == "robust":
        terrain = job.cache.terrain(job.resolution)
    else:
        terrain = terrain_from_points(cloud.points, job.algorithm, job.resolution)
    data = terrain_json(terrain)
    report = SegmentReport(
        inputs=job.echo(), regions=data["regions"], edges=data["edges"],
        cloud={"path": job.cloud.source, "points": len(cloud.points)}, algorithm=job.algorithm,
        resolution=terrain.segmentation.hmap.resolution, height_map=data["height_map"], voxels=data["voxels"],
        non_planar_cells=data["non_planar_cells"],
    )  # fmt: skip
    if png is not None:
        from baseplace.viz.regions import plot_regions

        plot_regions(terrain.segmentation, terrain.graph, png)
        report.outputs["png"] = str(png)
    report.timings_ms = {"load": (t_load - t0) * 1e3, **data.get("timings_ms", {})}
    report.timings_ms["total"] = (time.perf_counter() - t0) * 1e3
    return report
