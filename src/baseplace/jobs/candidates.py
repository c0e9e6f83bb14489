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
from baseplace.jobs.inputs import (
    CHECK_MARGIN,
    PLOT_SUFFIXES,
    CloudInput,
    Progress,
    ReachBound,
    bag_stamp,
    base_xyyaw,
    check_in_reach,
    check_object_yaw,
    check_on_scene,
    grid_bounds,
    load_robot,
    map_output,
    map_timing,
    occupancy_grid,
    out_path,
    parse_xyz,
    world_cloud,
    write_mcap,
)
from baseplace.jobs.place import motion_and_robustness_json
from baseplace.jobs.report import CandidatesReport, NoResultError, PoseRecord, RobotRef, path_json
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from pathlib import Path

    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.robustness import RobustnessSettings
    from baseplace.placement.scene_cache import SceneCache
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import OccupancyGrid


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
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: the
            cloud's voxels and, per grasped object, the collision environments kept between
            queries (the service).
    """

    object: str | Sequence[float]
    occupancy: OccupancyGrid | str | None = None
    cloud: CloudInput = field(default_factory=CloudInput)
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
            "obstacles": list(self.obstacles),
        }  # fmt: skip

    def check_outputs(self) -> tuple[Path | None, Path | None]:
        """The PNG and MCAP outputs (and the fused cloud's), checked before any work.

        Front ends call it before they build the settings, whose imports take seconds.
        """
        out_path(self.cloud.fused_out, "--fused-out", (".bt",))
        return out_path(self.png, "--png", PLOT_SUFFIXES), out_path(self.mcap, "--mcap", (".mcap",))


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


def candidates_job(job: CandidatesJob, progress: Progress | None = None) -> CandidatesReport:
    """Verified placement candidates for grasping at ``job.object``, best first.

    Raises:
        InputError: bad input (no grid, an object outside it or in an obstacle, an unwritable output).
        NoResultError: no verified candidate; ``report`` lists the rejected positions and why.
    """
    if job.method not in ("radial", "irm"):
        raise InputError(f"unknown method {job.method!r}; valid: irm, radial")
    png, mcap = job.check_outputs()  # outputs first: before the imports and any work
    from baseplace.geometry.poses import BasePose
    from baseplace.navigation.gridnav import GridNavigator
    from baseplace.placement.candidates import RadialSettings, motion_costs, pickup, radial_search
    from baseplace.placement.irm_candidates import (
        IrmSettings,
        grasp_poses,
        grasp_standoff,
        irm_candidates,
        verify_candidates,
    )
    from baseplace.placement.robustness import RobustnessSettings
    from baseplace.placement.scene_cache import object_key
    from baseplace.reachability.cache import resolve_map
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment, contact_groups
    from baseplace.world.grasped_object import GraspedObject, find_grasped_object, parse_grasped_object
    from baseplace.world.obstacles import check_clear_of, obstacles_key, parse_obstacles

    t0 = time.perf_counter()
    robust = job.robustness or RobustnessSettings()
    p_o = parse_xyz(job.object, "--object")
    robot_pose = None if job.robot_pose is None else base_xyyaw(job.robot_pose, "--robot-pose")
    check_object_yaw(job.object_shape, "--object-shape")
    shape = parse_grasped_object(job.object_shape, "--object-shape")
    obstacles = parse_obstacles(job.obstacles)
    check_clear_of(obstacles, p_o, ["--object"])
    grid = occupancy_grid(job.occupancy, job.cloud.bag, job.cloud)
    if grid is None:
        raise InputError("give --occupancy MAP.yaml or --bag FILE --map-topic TOPIC")
    robot = load_robot(job.robot)
    # before the map: an object no base on the grid brings within reach, a robot off the grid
    arm_name = job.arm
    if arm_name is None and not isinstance(job.map, str):  # else the map file's arm, not read yet: every arm
        arm_name = robot.spec.default_arm if job.map is None else job.map.info.arm
    standoff = grasp_standoff(robot, arm_name) if job.standoff is None else job.standoff
    scene, bounds = "the occupancy grid's bounds", grid_bounds(grid)
    check_in_reach(p_o[None], ["--object"], bounds, scene, ReachBound.of_robot(robot, arm_name), robot.name,
                   extra=abs(standoff))  # fmt: skip
    if robot_pose is not None:
        check_on_scene(robot_pose, "--robot-pose", bounds, scene, CHECK_MARGIN + grid.resolution)
    t_map = time.perf_counter()
    map_choice = resolve_map(robot, job.map, job.arm, progress)
    rmap, map_s = map_choice.rmap, time.perf_counter() - t_map
    arm = robot.arm(rmap.info.arm)
    settings = RadialSettings.for_robot(robot, rmap)
    check_object(grid, p_o, settings.d_max)
    t_load = time.perf_counter()
    points = world_cloud(job.cloud).points if job.cloud.given else None
    cache = job.cache if points is not None else None
    # only the hand may touch the object's own voxels (found at the object or given by its shape)
    grasped = shape if shape != "auto" else None
    if shape == "auto" and points is not None:
        grasped = find_grasped_object(points, p_o) if cache is None else cache.grasped_object(p_o)
    held = grasped if isinstance(grasped, GraspedObject) else None

    def environments() -> tuple[Any, Any, Any]:
        """The verification's environment, and the groups and object voxels it was built from."""
        voxels = VoxelMap(0.025, np.zeros((0, 3), np.int64))
        if points is not None:
            voxels = VoxelMap.from_points(points) if cache is None else cache.shared(
                ("voxels", 0.025), lambda: VoxelMap.from_points(points))  # fmt: skip
        groups, object_voxels = contact_groups(voxels, voxels, held, points)
        environment = Environment(robot, groups, grasped=object_voxels, hand_arm=job.arm, shapes=obstacles)
        return environment, groups, object_voxels

    if cache is None:
        environment, groups, object_voxels = environments()
    else:  # per robot, arm and grasped object, kept for the scene's next queries
        environment, groups, object_voxels = cache.per_object(
            ("candidates", robot, job.arm, object_key(held), obstacles_key(obstacles)), environments
        )
    motion = None
    if job.motion is not None:  # the way to the pre-grasp must avoid the object too
        from baseplace.placement.motion import MotionChecker, transit_environment

        transit = transit_environment(robot, groups, object_voxels, obstacles)
        if transit is None:
            motion = MotionChecker(robot, arm, environment, None, job.motion)
        else:
            motion = MotionChecker(robot, arm, transit, environment, job.motion)
    grasps = grasp_poses(p_o, n=16, top_down=True, standoff=standoff, approach_axis=arm.approach_axis)
    rng = np.random.default_rng(job.seed)
    rejected: list[tuple[tuple[float, float], str]] = []
    t_search = time.perf_counter()
    if job.method == "radial":
        search = radial_search(p_o, settings, points, grid)
        rejected += [(r.xy, str(r.reason)) for r in search.rejected]
        verified, failed = verify_candidates(
            robot, rmap.info.arm, search.candidates, grasps, environment, rng, motion
        )
        rejected += [((c.pose.x, c.pose.y), why) for c, why in failed]
    else:
        verified = irm_candidates(robot, rmap, p_o, grasps, environment, grid, IrmSettings(), rng, motion)
    t_verify = time.perf_counter()
    if robust.samples > 0:
        from baseplace.placement.robustness import score_candidates

        verified = score_candidates(arm, environment, grasps, verified, robust)
        too_low = [c for c in verified if c.robustness is not None and c.robustness.rate < robust.minimum]
        rejected += [((c.pose.x, c.pose.y), "robustness") for c in too_low]
        verified = [c for c in verified if c not in too_low]
    start = robot_pose if robot_pose is not None else np.r_[p_o[:2], 0.0]
    costs = motion_costs(verified, p_o, BasePose(*start)) if verified else np.zeros(0)
    order = np.argsort(costs, kind="stable")
    if robust.rank == "robustness":  # most robust first, motion cost breaks ties
        rates = np.array([-(c.robustness.rate if c.robustness else 0.0) for c in verified])
        order = np.lexsort((costs, rates))
    ranked = [verified[i] for i in order]
    t_rank = time.perf_counter()
    route = chosen = None
    if robot_pose is not None and ranked:
        navigator = GridNavigator(grid, settings.r_r)
        if robust.rank == "robustness":  # in the robustness order: the first the planner reaches
            for c in ranked:
                result = pickup([c], p_o, BasePose(*robot_pose), navigator)
                if result.succeeded:
                    route, chosen = result.path, c
                    break
        else:  # seed 004 Algorithm 2: by motion cost from the robot, the first the planner reaches
            result = pickup(ranked, p_o, BasePose(*robot_pose), navigator)
            route, chosen = result.path, result.chosen
    rows = [
        {**PoseRecord.from_xyyaw(c.pose.x, c.pose.y, c.pose.yaw).to_json(),
         "distance": round(c.distance, 4), "motion_cost": round(float(costs[i]), 4), "method": c.method,
         "reachability": round(c.reachability, 5), "grasp": grasps[c.grasp].round(5).tolist(),
         "joints": {} if c.joints is None else dict(zip(c.joint_names, np.round(c.joints, 6).tolist(), strict=True)),
         **motion_and_robustness_json(None if c.motion is None else [c.motion], c.robustness)}
        for i, c in zip(order, ranked, strict=True)
    ]  # fmt: skip
    failures: dict[str, int] = {}
    for _, why in rejected:
        failures[why] = failures.get(why, 0) + 1
    if robot_pose is not None and ranked and route is None:
        failures["no_path"] = len(ranked)
    report = CandidatesReport(
        robot=RobotRef.of(robot, rmap.info.arm), inputs=job.echo(), failures=failures, method=job.method,
        object=[float(v) for v in p_o],
        robot_pose=None if robot_pose is None else PoseRecord.from_xyyaw(*robot_pose), candidates=rows,
        rejected=[{"x": round(xy[0], 4), "y": round(xy[1], 4), "reason": why} for xy, why in rejected],
        path=None if route is None or chosen is None else path_json(route.poses),
        object_shape={"requested": job.object_shape,
                      "allowed": grasped.to_json() if isinstance(grasped, GraspedObject) else None},
        settings={"r_r": settings.r_r, "d_min": settings.d_min, "d_max": round(settings.d_max, 4),
                  "theta": round(settings.theta, 5), "k_obs": settings.k_obs, "grasp_standoff": standoff},
    )  # fmt: skip
    if png is not None:
        from baseplace.viz.candidates import plot_candidates

        plot_candidates(grid, p_o, ranked, rejected, png, robot_pose, None if route is None else route.poses,
                        f"{job.method} candidates for {robot.name}: {len(ranked)} verified, {len(rejected)} rejected")  # fmt: skip
        report.outputs["png"] = str(png)
    if mcap is not None:
        T_c = [PoseRecord.from_xyyaw(c.pose.x, c.pose.y, c.pose.yaw).T_world_base for c in ranked]
        world = job.cloud.bag.world_frame if job.cloud.bag is not None else "map"
        write_mcap(mcap, world, bag_stamp(job.cloud), candidates=T_c, placements=T_c[:1],
                   paths=[] if route is None else [route.poses])  # fmt: skip
        report.outputs["mcap"] = str(mcap)
    now = time.perf_counter()
    report.outputs.update(map_output(map_choice))
    report.timings_ms = {"load": (t_load - t0 - map_s) * 1e3, **map_timing(map_choice, map_s), "cloud": (t_search - t_load) * 1e3,
                         "search": (t_verify - t_search) * 1e3, "robustness": (t_rank - t_verify) * 1e3,
                         "navigation": (now - t_rank) * 1e3, "total": (now - t0) * 1e3}  # fmt: skip
    if not ranked:
        raise NoResultError(
            f"no verified candidate ({job.method}); {len(rejected)} positions rejected "
            f"({', '.join(sorted({why for _, why in rejected})) or 'none tried'})",
            report,
        )
    return report
