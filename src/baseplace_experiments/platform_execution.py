"""Issue 20 item 3: seed 000's platform scenes executed with a drawn navigation error and the reaching motion.

The scenes are those of seed 000's Table II experiment (:mod:`baseplace_experiments.osrm_experiment`:
floor, inclined ramps and raised tilted platforms, a tray of bottle-sized objects on a pedestal),
the queries its ground-truth-reachable top-down grasps. A method chooses a base pose from the noisy
cloud; the robot drives there and stops off it, and then re-plans. :class:`PlatformOracle` judges
that attempt on the scene's *true* geometry, independently of the method:

* **Where it stops**: a draw of the navigation error (:class:`~baseplace.placement.robustness.BaseErrorModel`,
  default sigma 3 cm and 2 deg) in the frame of the base, which lies in its support plane
  (:func:`drawn_on_plane`: the offset along the base's own x and y axes, the heading about its
  z axis, the plane normal). The base then rests on the *true* surface under the drawn position
  (:func:`seated`: origin on the true plane there, z along its normal, heading kept).
* **Drivable region** (:meth:`PlatformOracle.region`): the robot's footprint outline at the drawn
  pose must lie on one support region of the true scene: on the floor, clear of every inclined
  plane's footprint and of the box, inside the scene; on an inclined plane, inside that plane's
  footprint and clear of the box. Else the draw fails with ``off_region`` (a base straddling a
  plane's edge does not stand on a plane).
* **Grasp and reaching motion**: :meth:`~baseplace_experiments.execution.ExecutionOracle.execute`
  on the true solids (:func:`true_scene_shapes`): collision-free IK of the grasp from the drawn
  pose (stowed + 15 random starts, pinocchio FK within 1 mm / 0.01 rad, coal on the true shapes);
  the robot's own planner (:class:`~baseplace.placement.motion.MotionChecker` on its voxels of the
  noisy cloud, with the check budget) plans the reaching motion; the path is checked state by
  state on the true shapes: nothing touched in the transit, only the hand may touch the grasped
  object, and only in the last approach segment.

True solids: the tray (pedestal, bottom, walls), every object (the grasped one only the hand may
touch), every inclined plane as a solid block (its tilted top down to the floor), and the floor.
The surface the base stands on is lowered by :data:`SUPPORT_SINK` (the wheels rest on it; the
floor is lowered too, since a ramp's low edge meets it); every other surface is exact.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import shapely
from numpy.typing import ArrayLike
from shapely.geometry import Polygon

from baseplace.errors import BaseplaceError
from baseplace.geometry.poses import BasePose, FloatArray
from baseplace.placement.motion import MotionChecker, MotionSettings, transit_environment
from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings, place, place_obstacles
from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.sim.scenes import Plane, Scene
from baseplace.terrain.polygons import footprint_outline
from baseplace.world.environment import Environment, HandFilter, contact_groups
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.execution_experiment import summarise_execution
from baseplace_experiments.osrm_experiment import (
    SCENE_CLASSES,
    ExperimentSettings,
    GroundTruth,
    experiment_scene,
    grasp_candidates,
    grasped_shape,
    true_solids,
)
from baseplace_experiments.table_grid import RobotShapes, TrueShape

SUPPORT_SINK = 0.02
"""The support surface's solid is lowered by this [m]: the base resting on it is no collision."""
FLOOR_DEPTH = 0.1
"""Thickness [m] of the floor slab and how far below z = 0 the inclined blocks reach."""


def drawn_on_plane(T_world_base: ArrayLike, offsets: ArrayLike) -> FloatArray:
    """(S, 4, 4) base poses: ``T_world_base`` (4, 4) moved by (S, 3) offsets (dx, dy, dyaw) in its own frame.

    The base's x and y axes lie in its support plane and z is the plane's normal, so the drawn
    poses stay on the plane: ``T @ Trans(dx, dy, 0) @ Rz(dyaw)``. The error model is isotropic in
    xy, so drawing in the base frame instead of the world frame changes no distribution on a
    level floor.
    """
    return np.asarray(T_world_base, dtype=float) @ BasePose.batch_matrix(offsets)


def seated(T_world_base: ArrayLike, plane: Plane) -> FloatArray:
    """The base pose (4, 4) resting on the true ``plane`` at its xy: origin on the plane, z its normal.

    The heading is kept: the new x axis is the old one projected into the plane.
    """
    T = np.asarray(T_world_base, dtype=float)
    n = plane.normal
    x = T[:3, 0] - np.dot(T[:3, 0], n) * n
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2] = x, np.cross(n, x), n
    out[:2, 3] = T[:2, 3]
    out[2, 3] = float(plane.z(T[None, :2, 3])[0])
    return out


def _convex(name: str, vertices: FloatArray) -> TrueShape:
    points = coal.StdVec_Vec3s()
    for v in np.asarray(vertices, dtype=float):
        points.append(v)
    hull = coal.Convex.convexHull(points, False, "")
    return TrueShape(name, hull, np.eye(4))


def plane_block(plane: Plane, sink: float = 0.0) -> TrueShape:
    """An inclined plane as a solid: its footprint from ``FLOOR_DEPTH`` below the floor up to its top, less ``sink``."""
    corners = plane.polygon
    top = plane.z(corners) - sink
    bottom = np.full(len(corners), -FLOOR_DEPTH)
    vertices = np.vstack([np.c_[corners, top], np.c_[corners, bottom]])
    return _convex(f"plane {plane.id}", vertices)


def true_scene_shapes(scene: Scene, support: int, grasped: int) -> tuple[list[TrueShape], TrueShape]:
    """(obstacles, grasped object) of the true scene for a base standing on plane ``support``.

    ``grasped``: index into ``scene.objects``. The floor and the support plane are lowered by
    :data:`SUPPORT_SINK` (module docstring).
    """
    ex, ey = scene.settings.extent
    floor = np.eye(4)
    floor[2, 3] = -SUPPORT_SINK - FLOOR_DEPTH / 2
    shapes = [TrueShape("floor", coal.Box(ex + 4.0, ey + 4.0, FLOOR_DEPTH), floor)]
    for plane in scene.planes[1:]:
        shapes.append(plane_block(plane, SUPPORT_SINK if plane.id == support else 0.0))
    held: TrueShape | None = None
    for name, solid in true_solids(scene).items():
        for k, (geometry, T) in enumerate(solid):
            shape = TrueShape(f"{name} {k}" if len(solid) > 1 else name, geometry, T)
            if name == f"object{grasped}":
                held = shape
            else:
                shapes.append(shape)
    if held is None:
        raise ValueError(f"the scene has no object {grasped}")
    return shapes, held


@dataclass(frozen=True)
class Region:
    """Where a drawn base pose stands: its support plane's id, or None with why not."""

    support: int | None
    reason: str = ""


class PlatformOracle:
    """Execution of a grasp from a drawn base pose on the true platform scene (module docstring).

    Args:
        robot: the robot.
        shapes: its geometry model (:class:`RobotShapes`, built once).
        scene: the true scene.
        grasped: index of the grasped object in ``scene.objects``.
        settings: IK and path settings of :class:`ExecutionOracle`.
    """

    def __init__(self, robot: Robot, shapes: RobotShapes, scene: Scene, grasped: int,
                 settings: ExecutionSettings | None = None) -> None:  # fmt: skip
        self.robot = robot
        self.shapes = shapes
        self.scene = scene
        self.grasped = grasped
        self.settings = settings or ExecutionSettings()
        self.outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
        self._planes = [Polygon(p.polygon) for p in scene.planes]
        self._box = None if scene.box is None else Polygon(scene.box.polygon)
        x0, y0, x1, y1 = scene.bounds
        self._inside = shapely.box(x0, y0, x1, y1)
        self._oracles: dict[int, ExecutionOracle] = {}

    def footprint(self, T_world_base: ArrayLike) -> Polygon:
        """The footprint outline at the base pose (4, 4), projected onto xy."""
        T = np.asarray(T_world_base, dtype=float)
        local = np.c_[self.outline, np.zeros(len(self.outline))]
        return Polygon((local @ T[:3, :3].T + T[:3, 3])[:, :2])

    def region(self, T_world_base: ArrayLike) -> Region:
        """The true support plane the footprint at the (nominal or drawn) pose stands on wholly, if any."""
        T = np.asarray(T_world_base, dtype=float)
        sid = int(self.scene.surface_id(T[None, :2, 3])[0])
        if sid < 0:
            return Region(None, "centre on the box or outside the scene")
        foot = self.footprint(T)
        if self._box is not None and foot.intersects(self._box):
            return Region(None, "footprint on the box")
        if sid == 0:
            if not foot.within(self._inside):
                return Region(None, "footprint outside the scene")
            if any(foot.intersects(p) for p in self._planes[1:]):
                return Region(None, "footprint across a plane's edge")
            return Region(0)
        if not foot.within(self._planes[sid]):
            return Region(None, "footprint across a plane's edge")
        return Region(sid)

    def oracle(self, support: int) -> ExecutionOracle:
        """The IK + collision + motion oracle for a base on plane ``support`` (cached)."""
        if support not in self._oracles:
            shapes, held = true_scene_shapes(self.scene, support, self.grasped)
            self._oracles[support] = ExecutionOracle(self.shapes, shapes, held, self.settings)
        return self._oracles[support]

    def execute(self, T_drawn: ArrayLike, grasp: ArrayLike, planner: MotionChecker,
                rng: np.random.Generator) -> tuple[str, FloatArray | None]:  # fmt: skip
        """Outcome of one attempt from the drawn pose (4, 4), and the pose the base rests at.

        Outcomes: ``off_region`` (no drivable region holds the footprint), else those of
        :meth:`ExecutionOracle.execute` ("ok", "no_grasp", "no_motion", "motion_collision").
        """
        T = np.asarray(T_drawn, dtype=float)
        sid = int(self.scene.surface_id(T[None, :2, 3])[0])
        if sid < 0:
            return "off_region", None
        T_rest = seated(T, self.scene.planes[sid])
        where = self.region(T_rest)
        if where.support is None:
            return "off_region", T_rest
        return self.oracle(where.support).execute(T_rest, np.asarray(grasp)[None], planner, rng), T_rest


PLATFORM_METHODS = ("TO", "MR", "MRTO", "default", "robust")
"""Seed 000's strategies (its checks: IK + collision at the exact pose), baseplace's default (MR
with the reaching-motion check) and the robust ranking (the same, ranked by robustness)."""


def method_settings(
    method: str, motion: MotionSettings, robust: RobustnessSettings, tries: int = 100
) -> PlaceSettings:
    """The :class:`PlaceSettings` of a method of :data:`PLATFORM_METHODS`.

    The default's robustness score only annotates its placements (ranking by reachability, no
    minimum), so it is not computed here: the choice is the same.
    """
    # stand_on "any": seed 000's scenes count placements on every planar region, raised ones too
    if method in ("TO", "MR", "MRTO"):
        return PlaceSettings(strategy=method, tries=tries, stand_on="any", **POSE_ONLY_CHECKS)
    if method == "default":
        return PlaceSettings(
            tries=tries, motion=motion, robustness=RobustnessSettings(samples=0), stand_on="any"
        )
    if method == "robust":
        return PlaceSettings(tries=tries, motion=motion, robustness=robust, stand_on="any")
    raise ValueError(f"unknown method {method!r}; choose from {PLATFORM_METHODS}")


def _object_index(scene: Scene, grasp: FloatArray, tool_offset: float = 0.151) -> int:
    """The scene object whose axis is nearest the grasp point (``tool_offset`` ahead of the TCP)."""
    point = grasp[:3, 3] + tool_offset * grasp[:3, 0]
    d = [math.hypot(o.center[0] - point[0], o.center[1] - point[1]) for o in scene.objects]
    return int(np.argmin(d))


def platform_scene_trials(robot: Robot, rmap: ReachabilityMap, shapes: RobotShapes, seed: int, class_index: int,
                          k: int, queries: int, draws: int, motion: MotionSettings, robust: RobustnessSettings,
                          s: ExperimentSettings | None = None,
                          classes: tuple[tuple[str, int], ...] = SCENE_CLASSES) -> list[dict[str, Any]]:  # fmt: skip
    """The first ``queries`` ground-truth-reachable grasps of scene k of a class, executed per method; JSON-ready.

    The scene, its noisy cloud and terrain, its grasp candidates and the ground truth are those of
    :func:`~baseplace_experiments.osrm_experiment.osrm_scene` with ``ExperimentSettings(seed=seed)``.
    Per query: every method of :data:`PLATFORM_METHODS` chooses one placement (N = 100 tries,
    M = 1); ``draws`` navigation errors (the same for every method) are executed by
    :class:`PlatformOracle` with the robot's planner (``motion``) on its voxels of the cloud.
    """
    import dataclasses

    s = dataclasses.replace(s or ExperimentSettings(), seed=seed)
    rng, scene, points, terrain = experiment_scene(s, class_index, k, classes)
    arm = robot.arm(rmap.info.arm)
    grasps, objects, _ = grasp_candidates(
        scene, rng, s.grasps_per_scene, hand=HandFilter(robot, rmap.info.arm)
    )
    truth = GroundTruth()
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    obstacles = place_obstacles(terrain, PlaceSettings(stand_on="any"), outline)
    out: list[dict[str, Any]] = []
    for g, (grasp, obj) in enumerate(zip(grasps, objects, strict=True)):
        if len(out) >= queries:
            break
        if not truth.reachable(robot, rmap, scene, grasp, rng):
            continue
        q = len(out)
        index = _object_index(scene, grasp)
        assert grasped_shape(scene.objects[index]).kind == obj.kind
        groups, object_voxels = contact_groups(terrain.voxels, obstacles, obj)
        hand_env = Environment(robot, groups, grasped=object_voxels, hand_arm=rmap.info.arm)
        transit = transit_environment(robot, groups, object_voxels)
        planner = (
            MotionChecker(robot, arm, hand_env, None, motion)
            if transit is None
            else MotionChecker(robot, arm, transit, hand_env, motion)
        )
        oracle = PlatformOracle(robot, shapes, scene, index)
        offsets = BaseErrorModel().sample(np.random.default_rng([50_000 + seed, class_index, k, q]), draws)
        entry: dict[str, Any] = {"seed": seed, "class": list(classes[class_index]), "scene": k, "grasp": g,
                                 "object": index, "methods": {}}  # fmt: skip
        for m, method in enumerate(PLATFORM_METHODS):
            t0 = time.perf_counter()
            try:
                res = place(robot, rmap, points, grasp, method_settings(method, motion, robust),
                            np.random.default_rng([seed, class_index, k, q, m]), terrain=terrain,
                            grasped=obj)  # fmt: skip
                found = res.placements[0].T_world_base if res.placements else None
                note = (
                    "" if found is not None else ",".join(f"{r}:{n}" for r, n in sorted(res.failures.items()))
                )
            except BaseplaceError as exc:
                found, note = None, type(exc).__name__
            t_plan = time.perf_counter() - t0
            e: dict[str, Any] = {"plan_s": round(t_plan, 3)}
            if found is None:
                e.update(pose=None, note=note, outcomes=["no_placement"] * draws, success=0)
            else:
                nominal = oracle.region(
                    seated(found, scene.planes[max(0, int(scene.surface_id(found[None, :2, 3])[0]))])
                )
                exec_rng = np.random.default_rng([60_000 + seed, class_index, k, q])
                outcomes = [
                    oracle.execute(T, grasp, planner, exec_rng)[0] for T in drawn_on_plane(found, offsets)
                ]
                # diagnostic, not in the success rate: the same execution from the chosen pose itself
                at_nominal = oracle.execute(
                    found, grasp, planner, np.random.default_rng([70_000 + seed, class_index, k, q])
                )[0]
                e.update(pose=[round(float(v), 3) for v in found[:3, 3]], nominal_support=nominal.support,
                         nominal_note=nominal.reason, outcomes=outcomes, at_nominal=at_nominal,
                         success=sum(o == "ok" for o in outcomes))  # fmt: skip
            entry["methods"][method] = e
        out.append(entry)
    return out


def summarise_platform(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """Per method: the table grid's summary, plus outcomes from the chosen pose itself and queries placed."""
    out = summarise_execution(trials, PLATFORM_METHODS)
    for m, e in out.items():
        e["at_nominal"] = {o: sum(t["methods"][m].get("at_nominal") == o for t in trials)
                           for o in ("ok", "off_region", "no_grasp", "no_motion", "motion_collision")}  # fmt: skip
        e["queries_with_placement"] = sum(t["methods"][m]["pose"] is not None for t in trials)
    return out


__all__ = [
    "FLOOR_DEPTH",
    "PLATFORM_METHODS",
    "SUPPORT_SINK",
    "PlatformOracle",
    "Region",
    "drawn_on_plane",
    "method_settings",
    "plane_block",
    "platform_scene_trials",
    "seated",
    "summarise_platform",
    "true_scene_shapes",
]
