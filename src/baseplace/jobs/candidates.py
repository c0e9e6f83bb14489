"""The ``candidates`` job: verified base placement candidates around an object (seed 004).

Composes the radial search (seed 004 Algorithm 1) or the reachability-map candidates, the shared
verification (IK for one of the grasps, whole robot against the cloud's voxels, optional
reaching-motion check), the robustness score, the ranking by motion cost and, with the robot's
pose, the pickup loop (seed 004 Algorithm 2: the first candidate the grid planner reaches).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose
from baseplace.jobs import inputs
from baseplace.jobs.report import (
    CandidatesReport,
    NoResultError,
    RobotRef,
    path_json,
    placement_row,
)
from baseplace.robots.defaults import DEFAULT_ROBOT
from baseplace.world.clearance import check_clearance

if TYPE_CHECKING:
    from pathlib import Path

    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.robustness import RobustnessSettings
    from baseplace.placement.scene_cache import SceneCache
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import OccupancyGrid


NO_GRID = "give --occupancy MAP.yaml or --bag FILE --map-topic TOPIC"
"""The error for candidates asked without an occupancy grid (seed 004's candidates stand on one)."""


@dataclass
class CandidatesJob:
    """The inputs of :func:`candidates_job`.

    Attributes:
        object: grasp point "x y z" [m] in the map frame (text or 3 numbers).
        occupancy: occupancy grid (map_server YAML or loaded), or the cloud's bag map topic.
        cloud: RGB-D cloud in the map frame (optional): obstacles and the grasped object.
        robot_pose: the robot's pose "x y yaw" [m, rad]: rank by motion cost from it and plan a path.
        method: radial (seed 004 Algorithm 1) or irm (reachability map).
        robot, arm, map: as in :class:`~baseplace.jobs.place.PlaceJob`.
        standoff: TCP distance behind the grasp point [m] (None: the robot's default).
        seed: random seed.
        object_shape: the grasped object spec (auto, none, box ..., cylinder ..., points FILE).
        motion: the reaching-motion check (None: off).
        robustness: the robustness score and ranking (None: defaults).
        png, mcap: also write a plot / an MCAP recording here.
        obstacles: collision objects given by hand, as ``place``'s (box, cylinder or mesh file).
        clearance: as ``place``'s (:attr:`~baseplace.placement.pipeline.PlaceSettings.clearance`;
            None: derived).
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: the
            cloud's voxels and, per grasped object, the collision environments kept between
            queries (the service).
    """

    object: str | Sequence[float]
    occupancy: OccupancyGrid | str | None = None
    cloud: inputs.CloudInput = field(default_factory=inputs.CloudInput)
    robot_pose: str | Sequence[float] | None = None
    method: str = "radial"
    robot: Robot | str = DEFAULT_ROBOT
    arm: str | None = None
    map: ReachabilityMap | str | None = None
    standoff: float | None = None
    seed: int = 0
    object_shape: str = "auto"
    motion: MotionSettings | None = None
    robustness: RobustnessSettings | None = None
    png: str | None = None
    mcap: str | None = None
    cache: SceneCache | None = field(default=None, repr=False, compare=False)
    obstacles: Sequence[str] = ()
    clearance: float | None = None

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {
            "object": self.object if isinstance(self.object, str) else [float(v) for v in self.object],
            "occupancy": self.occupancy if isinstance(self.occupancy, str | None) else "grid", **self.cloud.echo(),
            "robot_pose": self.robot_pose if isinstance(self.robot_pose, str | None) else list(self.robot_pose),
            "method": self.method, "robot": self.robot if isinstance(self.robot, str) else self.robot.name,
            "arm": self.arm, "map": self.map if isinstance(self.map, str | None) else "loaded",
            "standoff": self.standoff, "seed": self.seed, "object_shape": self.object_shape,
            "motion_check": self.motion is not None,
            "rank": "reachability" if self.robustness is None else self.robustness.rank,
            "obstacles": list(self.obstacles), "clearance": self.clearance,
        }  # fmt: skip

    def check_inputs(self) -> tuple[Path | None, Path | None, np.ndarray, np.ndarray | None]:
        """The inputs that need no library beyond numpy, checked before any work; parsed.

        The method, the outputs (PNG, MCAP, the fused cloud's), the object's position, the robot's
        pose, the object shape's yaw, that a grid is given (:data:`NO_GRID`) and, last, the cloud
        files' names. Front ends call it before they build the settings, whose imports take
        seconds, so that a mistyped argument is refused at once.

        Returns:
            The PNG and MCAP paths (None: not asked), the object "x y z" (3,) and the robot pose
            "x y yaw" (3,) or None.
        """
        if self.method not in ("radial", "irm"):
            raise InputError(f"unknown method {self.method!r}; valid: irm, radial")
        inputs.out_path(self.cloud.fused_out, "--fused-out", (".bt",))
        png = inputs.out_path(self.png, "--png", inputs.PLOT_SUFFIXES)
        mcap = inputs.out_path(self.mcap, "--mcap", (".mcap",))
        p_o = inputs.parse_xyz(self.object, "--object")
        robot_pose = None if self.robot_pose is None else inputs.base_xyyaw(self.robot_pose, "--robot-pose")
        inputs.check_object_yaw(self.object_shape, "--object-shape")
        check_clearance(self.clearance)
        if self.occupancy is None and (self.cloud.bag is None or self.cloud.bag.map_topic is None):
            raise InputError(NO_GRID)
        inputs.check_robot_name(self.robot, self.arm)
        inputs.check_map_file(self.map)
        self.cloud.check_paths()  # the files last: a mistyped option is named first
        return png, mcap, p_o, robot_pose


def check_object(grid: Any, p_o: np.ndarray, reach: float) -> None:
    """Clear errors for an object outside the map or buried in an obstacle (no free cell in reach)."""
    from scipy import ndimage

    x, y = float(p_o[0]), float(p_o[1])
    if not grid.inside(p_o[None, :2])[0]:
        raise InputError(f"--object ({x:.2f}, {y:.2f}) lies outside the occupancy grid {grid.source}")
    free = (grid.data >= 0) & (grid.data < 50)
    if not free.any():
        raise InputError(f"the occupancy grid {grid.source} has no free cell")
    gap = ndimage.distance_transform_edt(~free) * grid.resolution
    col, row = grid.world_to_cell(p_o[None, :2])[0]
    if gap[row, col] > reach:
        raise InputError(
            f"--object ({x:.2f}, {y:.2f}) lies inside an obstacle or unknown space: the nearest free cell is "
            f"{gap[row, col]:.2f} m away, beyond the arm's reach ({reach:.2f} m)"
        )


def candidates_job(job: CandidatesJob, progress: inputs.Progress | None = None) -> CandidatesReport:
    """Verified placement candidates for grasping at ``job.object``, best first.

    Raises:
        InputError: bad input (no grid, an object outside it or in an obstacle, an unwritable output).
        NoResultError: no verified candidate; ``report`` lists the rejected positions and why.
    """
    png, mcap, p_o, robot_pose = job.check_inputs()  # first: before the imports and any work
    from baseplace.placement.candidates import RadialSettings
    from baseplace.placement.irm_candidates import (
        grasp_poses,
        grasp_standoff,
        irm_settings_for,
        reach_margin_json,
    )
    from baseplace.placement.object_search import search_around_object
    from baseplace.placement.pipeline import object_checks
    from baseplace.placement.robustness import RobustnessSettings
    from baseplace.placement.verify import motion_failure_summary
    from baseplace.reachability.cache import resolve_map
    from baseplace.world.grasped_object import GraspedObject, find_grasped_object, parse_grasped_object
    from baseplace.world.obstacles import check_clear_of, parse_obstacles
    from baseplace.world.sensor_resolution import clearance_record

    t0 = time.perf_counter()
    robust = job.robustness or RobustnessSettings()
    shape = parse_grasped_object(job.object_shape, "--object-shape")
    obstacles = parse_obstacles(job.obstacles)
    check_clear_of(obstacles, p_o, ["--object"])
    grid = inputs.occupancy_grid(job.occupancy, job.cloud.bag, job.cloud)
    if grid is None:
        raise InputError(NO_GRID)
    robot = inputs.load_robot(job.robot)
    # before the map: an object no base on the grid brings within reach, a robot off the grid
    arm_name = job.arm
    if arm_name is None and not isinstance(job.map, str):  # else the map file's arm, not read yet: every arm
        arm_name = robot.spec.default_arm if job.map is None else job.map.info.arm
    standoff = grasp_standoff(robot, arm_name) if job.standoff is None else job.standoff
    scene, bounds = "the occupancy grid's bounds", inputs.grid_bounds(grid)
    inputs.check_in_reach(p_o[None], ["--object"], bounds, scene, inputs.ReachBound.of_robot(robot, arm_name), robot.name,
                   extra=abs(standoff))  # fmt: skip
    if robot_pose is not None:
        inputs.check_on_scene(
            robot_pose, "--robot-pose", bounds, scene, inputs.CHECK_MARGIN + grid.resolution
        )
    t_map = time.perf_counter()
    map_choice = resolve_map(robot, job.map, job.arm, progress)
    rmap, map_s = map_choice.rmap, time.perf_counter() - t_map
    arm = robot.arm(rmap.info.arm)
    settings = RadialSettings.for_robot(robot, rmap)
    check_object(grid, p_o, settings.d_max)
    t_load = time.perf_counter()
    points = inputs.world_cloud(job.cloud).points if job.cloud.given else None
    cache = job.cache if points is not None else None
    # only the hand may touch the object's own voxels (found at the object or given by its shape)
    grasped = shape if shape != "auto" else None
    if shape == "auto" and points is not None:
        grasped = find_grasped_object(points, p_o) if cache is None else cache.grasped_object(p_o)
    held = grasped if isinstance(grasped, GraspedObject) else None
    checks = object_checks(robot, rmap.info.arm, job.arm, points, held, job.motion, cache, obstacles,
                           job.clearance)  # fmt: skip
    grasps = grasp_poses(p_o, n=16, top_down=True, standoff=standoff, approach_axis=arm.approach_axis)
    t_search = time.perf_counter()
    found = search_around_object(robot, rmap, p_o, grasps, "irm" if job.method == "irm" else "radial", checks,
                                 grid, points, settings, robust, np.random.default_rng(job.seed), robot_pose)  # fmt: skip
    t_nav = time.perf_counter()
    ranked, rejected, route = found.placements, found.rejected, found.path
    rows = [placement_row(p, cost) for p, cost in zip(ranked, found.motion_costs, strict=True)]
    report = CandidatesReport(
        robot=RobotRef.of(robot, rmap.info.arm), inputs=job.echo(), failures=found.failures(), method=job.method,
        object=[float(v) for v in p_o],
        robot_pose=None if robot_pose is None else BasePose.from_xyyaw(*robot_pose), candidates=rows,
        rejected=[{"x": round(xy[0], 4), "y": round(xy[1], 4), "reason": why} for xy, why in rejected],
        path=None if route is None or found.chosen is None else path_json(route.poses),
        object_shape={"requested": job.object_shape,
                      "allowed": grasped.to_json() if isinstance(grasped, GraspedObject) else None},
        settings={"r_r": settings.r_r, "d_min": settings.d_min, "d_max": round(settings.d_max, 4),
                  "theta": round(settings.theta, 5), "k_obs": settings.k_obs, "grasp_standoff": standoff,
                  "reach_margin": reach_margin_json(irm_settings_for(robust)) if job.method == "irm" else None},
        clearance=clearance_record(checks.environment.clearance, checks.clearance_note, checks.noise_margin),
        motion_failures=dict(found.motion_failures),
    )  # fmt: skip
    if png is not None:
        from baseplace.viz.candidates import plot_candidates

        plot_candidates(grid, p_o, ranked, rejected, png, robot_pose, None if route is None else route.poses,
                        f"{job.method} candidates for {robot.name}: {len(ranked)} verified, {len(rejected)} rejected")  # fmt: skip
        report.outputs["png"] = str(png)
    if mcap is not None:
        T_c = [p.T_world_base for p in ranked]
        world = job.cloud.bag.world_frame if job.cloud.bag is not None else "map"
        inputs.write_mcap(mcap, world, inputs.bag_stamp(job.cloud), candidates=T_c, placements=T_c[:1],
                   paths=[] if route is None else [route.poses])  # fmt: skip
        report.outputs["mcap"] = str(mcap)
    now = time.perf_counter()
    report.outputs.update(inputs.map_output(map_choice))
    report.timings_ms = {"load": (t_load - t0 - map_s) * 1e3, **inputs.map_timing(map_choice, map_s), "cloud": (t_search - t_load) * 1e3,
                         **found.timings_ms, "navigation": (now - t_nav) * 1e3, "total": (now - t0) * 1e3}  # fmt: skip
    if not ranked:
        motion = motion_failure_summary(found.motion_failures)
        raise NoResultError(
            f"no verified candidate ({job.method}); {len(rejected)} positions rejected "
            f"({', '.join(sorted({why for _, why in rejected})) or 'none tried'})"
            + (f"; {motion}" if motion else ""),
            report,
        )
    return report
