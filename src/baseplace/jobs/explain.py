"""The ``explain`` job: why a robot can or cannot grasp one target from one base pose.

The "why not" answer of MoveIt's and REACH's users, for one base pose "x y yaw" and one TCP
target: the reachability map's value there (and whether the support test passed), IK (solved,
or the least residual over all its starts), every collision of the IK solution (robot link and
what it touched: another link, an obstacle, the support or the grasped object) and the reaching
motion. The checks are :func:`~baseplace.placement.pipeline.place`'s own
(:func:`~baseplace.placement.pipeline.scene_checks`, the same collision model, IK and motion
checker), run to the end instead of stopping at the first failure, so ``explain`` at a base pose
``place`` refused names the same link and object as the refusal.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, pose_json
from baseplace.jobs.inputs import (
    TARGET_AND_GRASP_POINT,
    CloudInput,
    Progress,
    base_xyyaw,
    check_map_file,
    check_robot_name,
    load_robot,
    map_output,
    map_timing,
    world_cloud,
)
from baseplace.jobs.report import Report, RobotRef
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.placement.pipeline import PlaceSettings
    from baseplace.placement.scene_cache import SceneCache
    from baseplace.placement.verify import Verifier
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.terrain.pipeline import Terrain
    from baseplace.world.obstacles import Obstacle


@dataclass
class ExplainJob:
    """The inputs of :func:`explain_job`.

    Attributes:
        base: base pose "x y yaw" [m, rad] (text or 3 numbers); on a scene the base stands on the
            planar region under (x, y), its heading yaw the x axis's in the world xy plane.
        target: TCP target "x y z roll pitch yaw" [m, rad], world frame (text or 6 numbers).
        grasp_point: instead of ``target``: the pose of the point between the fingertips (the arm
            spec's ``grasp_frame``), same format, as ``place``'s ``grasp_points``.
        map: reachability map: loaded, a file, or None for the cached default map.
        robot: built-in name, robot file or a loaded Robot.
        arm: the arm (None: the robot's default arm, or the map's).
        cloud: the scene cloud, as ``place`` takes it; none given: IK and self-collision only.
        object: the grasped object spec, as ``place``'s (auto, none, box ..., cylinder ..., points FILE).
        floor: add a floor plane at this height [m] under a cloud that shows none.
        obstacles: collision objects given by hand, as ``place``'s (box, cylinder or mesh file).
        settings: ``place``'s settings (the height-map resolution, the motion check); None: defaults.
        seed: random seed of IK's restarts and the motion planner.
        cache: a :class:`~baseplace.placement.scene_cache.SceneCache` of ``cloud.points``: the
            segmentation and collision environments kept between queries (the service).
    """

    base: str | Sequence[float] | None
    target: str | Sequence[float] | None
    map: ReachabilityMap | str | None = None
    robot: Robot | str = DEFAULT_ROBOT
    arm: str | None = None
    cloud: CloudInput = field(default_factory=CloudInput)
    object: str = "auto"
    floor: float | None = None
    settings: PlaceSettings | None = None
    seed: int = 0
    grasp_point: str | Sequence[float] | None = None
    cache: SceneCache | None = field(default=None, repr=False, compare=False)
    obstacles: Sequence[str] = ()

    def check_inputs(self) -> tuple[tuple[float, float, float], np.ndarray, str]:
        """The inputs that need no library beyond numpy, checked before any work; parsed.

        The base pose, the target (or grasp point), a floor without a cloud and, last, the cloud
        files' names. Front ends call it before they build the settings, whose imports take
        seconds, so that a mistyped argument is refused at once.

        Returns:
            The base "x y yaw", the target pose (4, 4) as given (the TCP's, or the grasp point's)
            and the option it was given with.
        """
        if self.base is None:
            raise InputError('give the base pose --base "x y yaw" [m, rad]')
        if self.target is not None and self.grasp_point is not None:
            raise InputError(TARGET_AND_GRASP_POINT)
        given: str | Sequence[float]
        if self.target is not None:
            given, option = self.target, "--target"
        elif self.grasp_point is not None:
            given, option = self.grasp_point, "--grasp-point"
        else:
            raise InputError('give the target --target "x y z roll pitch yaw" [m, rad] (the TCP pose) '
                             "or --grasp-point (the point between the fingertips)")  # fmt: skip
        x, y, yaw = base_xyyaw(self.base, "--base")
        T_target = _target(given, option)
        if self.floor is not None and not self.cloud.given:
            raise InputError("--floor adds a floor under a cloud: give --cloud too")
        check_robot_name(self.robot, self.arm)
        check_map_file(self.map)
        self.cloud.check_paths()
        return (x, y, yaw), T_target, option

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {
            "base": _echo(self.base), "target": _echo(self.target), "grasp_point": _echo(self.grasp_point),
            "map": self.map if isinstance(self.map, str | None) else "loaded",
            "robot": self.robot if isinstance(self.robot, str) else self.robot.name, "arm": self.arm,
            **self.cloud.echo(), "object": self.object, "floor": self.floor, "seed": self.seed,
            "motion_check": self.settings is None or self.settings.motion is not None,
            "obstacles": list(self.obstacles),
        }  # fmt: skip


def _echo(pose: str | Sequence[float] | None) -> str | list[float] | None:
    return pose if isinstance(pose, str | None) else [float(v) for v in pose]


@dataclass
class ExplainReport(Report):
    """``explain``: the checks of ``place`` at one base pose for one target, each to its end.

    Attributes:
        target: the TCP target "x y z roll pitch yaw" [m, rad], world frame.
        base: the base pose checked (pose fields) and ``region`` (the planar region under it, -1: none).
        map: ``value`` (the map's index with its support test), ``cell_value`` (the cell's index
            without it), ``support`` ("passed", "failed" or "off") and ``threshold``.
        footprint: ``checked`` and ``fits`` (inside the region's polygon).
        ik: ``solved``, ``starts``, ``position_error`` [m], ``rotation_error`` [rad] (of the
            solution, or of the least residual when unsolved) and ``joints`` (name -> value).
        collisions: each contact of the IK solution: ``link``, ``touched`` (as ``place`` names it)
            and ``kind`` ("self", "scene" or "grasped_object").
        motion: ``checked`` (false: no scene, no IK solution, a colliding grasp or the check off),
            ``found``, ``planned``, ``waypoints``, ``contacts`` (what blocked it) and ``reason``
            (why none was found, :data:`~baseplace.placement.motion.MOTION_FAILURES`; null otherwise).
        verdict: ``ok``, ``failed_check`` (``place``'s rejection reason: footprint, no_ik,
            collision, motion; null when ok) and ``summary`` (one line).
        object: the grasped object: requested, found, allowed.
    """

    kind: ClassVar[str] = "explain"
    target: str = ""
    base: dict[str, Any] = field(default_factory=dict)
    map: dict[str, Any] = field(default_factory=dict)
    footprint: dict[str, Any] = field(default_factory=dict)
    ik: dict[str, Any] = field(default_factory=dict)
    collisions: list[dict[str, str]] = field(default_factory=list)
    motion: dict[str, Any] = field(default_factory=dict)
    verdict: dict[str, Any] = field(default_factory=dict)
    object: dict[str, Any] = field(default_factory=dict)


def explain_job(job: ExplainJob, progress: Progress | None = None) -> ExplainReport:
    """Every check of ``place`` at ``job.base`` for ``job.target``, and a one-line verdict.

    Raises:
        InputError: a missing or malformed base pose or target, a bad scene or map.
    """
    from baseplace.geometry.poses import invert_transforms
    from baseplace.jobs.place import pose_text
    from baseplace.placement.pipeline import PlaceSettings, scene_checks, with_floor
    from baseplace.placement.verify import Candidate
    from baseplace.reachability.cache import resolve_map
    from baseplace.robots.ik import DampedLeastSquaresIK
    from baseplace.world.grasped_object import parse_grasped_object
    from baseplace.world.obstacles import check_clear_of, parse_obstacles

    t0 = time.perf_counter()
    (x, y, yaw), T_target, option = job.check_inputs()
    grasped = parse_grasped_object(job.object)
    obstacles = parse_obstacles(job.obstacles)
    settings = job.settings or PlaceSettings()
    robot = load_robot(job.robot)
    if job.grasp_point is not None:  # T_world_tcp = T_world_grasp T_grasp_tcp
        T_target = T_target @ np.linalg.inv(robot.T_tcp_grasp(job.arm))
    check_clear_of(obstacles, (T_target @ robot.T_tcp_grasp(job.arm))[:3, 3], [option])
    points = None
    if job.cloud.given:
        points = world_cloud(job.cloud).points
        points = points if job.floor is None else with_floor(points, job.floor)
    t_load = time.perf_counter()
    chosen = resolve_map(robot, job.map, job.arm, progress)
    rmap = chosen.rmap
    t_map = time.perf_counter()
    arm = robot.arm(rmap.info.arm)
    rng = np.random.default_rng(job.seed)
    object_json: dict[str, Any] = {"requested": job.object, "found": "none", "allowed": None}
    if points is not None:
        terrain = _terrain(points, settings) if job.cache is None else job.cache.terrain(settings.resolution)
        T_base, region = base_on_terrain(terrain, x, y, yaw)
        checks = scene_checks(robot, arm.name, points, terrain, T_target[None], settings, grasped, job.cache,
                              obstacles=obstacles)  # fmt: skip
        verifier = checks.verifier
        object_json["found"] = checks.grasped_note
        object_json["allowed"] = None if checks.grasped is None else checks.grasped.to_json()
    else:
        T_base, region = BasePose.batch_matrix([x, y, yaw])[0], -1
        verifier = _self_collision_only(robot, arm.name, T_target, obstacles)
    t_setup = time.perf_counter()
    value = _map_value(rmap, T_base, T_target)
    candidate = Candidate(T_base, region, value["value"])
    footprint = {"checked": region >= 0, "fits": verifier.footprint_fits(candidate)}
    solver = verifier.ik
    assert isinstance(solver, DampedLeastSquaresIK)  # scene_checks' solver
    ik = solver.attempt(invert_transforms(T_base) @ T_target, rng)
    ik_json = {"solved": ik.solved, "starts": ik.starts, "position_error": round(ik.position_error, 6),
               "rotation_error": round(ik.rotation_error, 6),
               "joints": dict(zip(arm.joint_names, np.round(ik.q, 6).tolist(), strict=True))}  # fmt: skip
    contacts = verifier.collisions(ik.q, T_base) if ik.solved else None
    collisions = [{"link": link, "touched": what, "kind": _kind_of(what)} for link, what in contacts or []]
    motion: dict[str, Any] = {
        "checked": False,
        "found": None,
        "planned": None,
        "waypoints": None,
        "contacts": [],
        "reason": None,
    }
    if ik.solved and contacts is None and verifier.motion is not None:
        found = verifier.motion.check(ik.q, T_base, T_target, seed=int(rng.integers(2**31 - 1)))
        motion = {"checked": True, "found": found is not None, "planned": None if found is None else found.planned,
                  "waypoints": None if found is None else len(found.waypoints),
                  "contacts": [{"link": link, "touched": what} for link, what in verifier.motion.last_contacts],
                  "reason": verifier.motion.last_failure}  # fmt: skip
    t_checks = time.perf_counter()
    verdict = _verdict(
        value, footprint, ik_json, collisions, motion, points is not None or bool(obstacles), settings
    )
    return ExplainReport(
        robot=RobotRef.of(robot, arm.name), inputs=job.echo(), outputs=map_output(chosen),
        failures={verdict["failed_check"]: 1} if verdict["failed_check"] else {},
        timings_ms={"load": (t_load - t0) * 1e3, **map_timing(chosen, t_map - t_load),
                    "collision_setup": (t_setup - t_map) * 1e3, "checks": (t_checks - t_setup) * 1e3},
        target=pose_text(T_target) if job.target is None else
        job.target if isinstance(job.target, str) else " ".join(f"{float(v):g}" for v in job.target),
        base={**pose_json(T_base), "region": region}, map=value, footprint=footprint, ik=ik_json,
        collisions=collisions, motion=motion, verdict=verdict, object=object_json,
    )  # fmt: skip


def _target(target: str | Sequence[float], option: str) -> np.ndarray:
    from baseplace.geometry.poses import parse_pose6, pose_from_xyz_rpy

    if isinstance(target, str):
        try:
            return parse_pose6(target)
        except InputError as exc:
            raise InputError(f"{option}: {exc}") from None
    values = np.asarray(target, dtype=float)
    if values.shape != (6,) or not np.isfinite(values).all():
        raise InputError(f"a target needs 6 finite numbers x y z roll pitch yaw, got {list(values)}")
    return np.asarray(pose_from_xyz_rpy(values))


def _terrain(points: np.ndarray, settings: PlaceSettings) -> Terrain:
    """The scene's segmentation, from the per-user cache as ``place`` reads it."""
    from baseplace.terrain.cache import cached_terrain

    return cached_terrain(points, resolution=settings.resolution)


def base_on_terrain(terrain: Terrain, x: float, y: float, yaw: float) -> tuple[np.ndarray, int]:
    """``T_world_base`` (4, 4) standing on the planar region under (x, y) [m], heading yaw [rad].

    The pose ``place``'s candidates take on that region (seed 000 III-A: the base's z axis along
    the plane's normal), turned so that its x axis points along yaw in the world xy plane; on no
    region, the flat pose at z = 0. Returns the pose and the region id (-1: none).
    """
    from baseplace.geometry.surface_poses import plane_base_poses, plane_frame

    seg = terrain.segmentation
    region = int(seg.region_at(np.array([[x, y]]))[0])
    if region < 0:
        return BasePose.batch_matrix([x, y, yaw])[0], -1
    plane = seg.regions[region]
    R0 = plane_frame(plane.normal)
    # the base x axis is R0 (cos g, sin g, 0): the gamma whose xy projection points along yaw
    c, s = np.linalg.solve(R0[:2, :2], [math.cos(yaw), math.sin(yaw)])
    gamma = math.atan2(s, c)
    return plane_base_poses(np.array([x]), np.array([y]), np.array([gamma]), plane.normal, plane.d)[0], region


def _self_collision_only(
    robot: Robot, arm_name: str, T_target: np.ndarray, obstacles: Sequence[Obstacle]
) -> Verifier:
    """The verification without a scene: IK, self-collision and the obstacles given (no motion, no footprint)."""
    from baseplace.placement.verify import Verifier
    from baseplace.robots.ik import DampedLeastSquaresIK
    from baseplace.terrain.polygons import footprint_outline
    from baseplace.world.environment import Environment

    arm = robot.arm(arm_name)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    return Verifier(arm, DampedLeastSquaresIK(arm), Environment(robot, {}, shapes=obstacles), T_target[None], {},
                    outline)  # fmt: skip


def _map_value(rmap: ReachabilityMap, T_world_base: np.ndarray, T_world_target: np.ndarray) -> dict[str, Any]:
    """The map's value of the target from the base, with and without its support test."""
    from baseplace.geometry.poses import invert_transforms

    T_base_tcp = np.ascontiguousarray(invert_transforms(T_world_base) @ T_world_target)
    value = rmap.value(T_base_tcp)
    cell = rmap.with_support(0, 0.0).value(T_base_tcp) if rmap.info.supported else value
    support = "off" if not rmap.info.supported else "passed" if value > 0 or cell == 0 else "failed"
    return {"value": round(float(value), 6), "cell_value": round(float(cell), 6), "support": support,
            "threshold": float(rmap.info.support_threshold) if rmap.info.supported else 0.0}  # fmt: skip


def _kind_of(touched: str) -> str:
    from baseplace.world.environment import GRASPED

    if touched.startswith("self: "):
        return "self"
    return "grasped_object" if touched == GRASPED else "scene"


def _verdict(value: dict[str, Any], footprint: dict[str, Any], ik: dict[str, Any], collisions: list[dict[str, str]],
             motion: dict[str, Any], scene: bool, settings: PlaceSettings) -> dict[str, Any]:  # fmt: skip
    """``place``'s verdict on this base pose (its first failing check) and one line saying why."""
    where = f"map value {value['value']:.3f}" + (
        " (support test failed)" if value["support"] == "failed" else ""
    )
    failed, why = None, ""
    if footprint["checked"] and not footprint["fits"]:
        failed, why = "footprint", "the base's footprint leaves its planar region"
    elif not ik["solved"]:
        failed = "no_ik"
        why = (f"IK failed from {ik['starts']} starts (closest {ik['position_error']:.3f} m and "
               f"{ik['rotation_error']:.3f} rad from the target)")  # fmt: skip
    elif collisions:
        touched: dict[str, list[str]] = {}
        for c in collisions:
            touched.setdefault(c["touched"], []).append(c["link"])
        failed = "collision"
        why = "; ".join(f"link{'s' if len(links) > 1 else ''} {', '.join(links)} touched {what}"
                        for what, links in touched.items())  # fmt: skip
    elif motion["checked"] and not motion["found"]:
        from baseplace.placement.motion import MOTION_FAILURES

        failed = "motion"
        blocked = motion["contacts"]
        why = (
            f"no reaching motion from the stowed arm: {MOTION_FAILURES.get(motion['reason'], motion['reason'])}"
            + (f" (link {blocked[0]['link']} touched {blocked[0]['touched']})" if blocked else "")
        )
    if failed is not None:
        return {"ok": False, "failed_check": failed, "summary": f"refused: {why}; {where}"}
    checks = "IK solved, no collision" + (", reaching motion found" if motion["checked"] else "")
    if not scene:
        checks += " with itself (no scene given)"
    elif settings.motion is None:
        checks += " (motion check off)"
    return {"ok": True, "failed_check": None, "summary": f"passes: {checks}; {where}"}
