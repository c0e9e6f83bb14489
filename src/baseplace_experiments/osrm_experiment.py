"""Seed 000's placement experiments (Tables I and II, Fig. 5) on generated scenes.

The protocol (issue 14), fixed before any result was looked at:

* Scene classes: flat, {small, medium, large} x {2, 4} inclined planes as seed 000 VI, and
  "incline-only": the tray in the middle of one 3.0-3.4 m inclined plane, beyond the arm's reach
  from the floor, so every placement must stand on the incline.
* Grasps come from a grasp planner that knows the scene's true shapes (:func:`grasp_candidates`):
  top-down draws on the objects whose open hand clears the true solids (tray, other objects).
  It never sees the verifier's voxels; no grasp is dropped by a check the placement runs.
* Ground truth, as seed 000 VI (:class:`GroundTruth`): a grasp counts if IK solves it from some
  base pose on a grid on the true surfaces with the footprint clear of other planes and the box;
  the arm's collisions are not checked (as in the seed).
* For every counted grasp each strategy runs Algorithm 2 on the noisy cloud with N = 100 tries and
  M = 1; only the hand may touch the grasped object (its true shape), everything else is an
  obstacle. The candidate sequence does not depend on N, so success at N = 1, 3, 10 and 100 is
  read from the try at which the first placement was verified.
* t_a is seed 000's "entire query": request to verified placement, including the OSRM and the
  collision environment (:func:`~baseplace.placement.pipeline.place`'s
  ``request_to_placement``); the segmentation, once per scene, is reported on its own.
* Development seeds (:data:`DEV_SEEDS`) for any parameter choice; tables from the disjoint
  held-out seeds (:data:`HELD_OUT_SEEDS`); the results record which.

The full run's tables are in docs/placement.md (``baseplace experiment osrm``).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from baseplace.errors import BaseplaceError, InputError
from baseplace.geometry.poses import FloatArray, invert_transforms, pose_from_xyz_rpy
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings, place
from baseplace.placement.verified import Placement
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.sim.scenes import BOX_SIZE, Box, Plane, Scene, SceneObject, SceneSettings, generate_scene
from baseplace.terrain.pipeline import Terrain, terrain_from_points
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import HandFilter
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.sensor_resolution import MIN_CLEARANCE
from baseplace_experiments.allowed_grasps import AllowedGrasps, Contact, ContactApproach, scene_solids
from baseplace_experiments.results import SeedSplit

SCENE_CLASSES = (
    ("flat", 0),
    ("small", 2),
    ("small", 4),
    ("medium", 2),
    ("medium", 4),
    ("large", 2),
    ("large", 4),
    ("incline-only", 1),
)
DEV_SEEDS = (1000,)
"""Seeds the experiment's parameters were chosen on (never reported as the tables)."""
HELD_OUT_SEEDS = (2026,)
"""Seeds the reported tables come from; disjoint from :data:`DEV_SEEDS`."""
SEEDS = SeedSplit(DEV_SEEDS, HELD_OUT_SEEDS)
"""Both, as recorded in the results file's provenance."""
PROTOCOL_FILE = "docs/protocols/osrm.md"
"""The protocol, committed before a held-out run (:func:`~baseplace_experiments.results.fixed_protocol`)."""
COLLISION_CLOUDS = ("noisy", "clean")
"""The clouds the method's collision model may come from (:attr:`ExperimentSettings.collision_cloud`)."""
BUDGETS = (1, 3, 10, 100)
"""Candidate budgets N at which success is reported."""
PAPER = {  # seed 000 Tables I and II: success rate [%]
    ("flat", 0): {"orm": 89.0, "TO": 87.1, "MR": 97.5, "MRTO": 94.6},
    ("small", 2): {"TO": 72.7, "MR": 87.8, "MRTO": 84.1}, ("small", 4): {"TO": 55.8, "MR": 77.9, "MRTO": 80.4},
    ("medium", 2): {"TO": 74.1, "MR": 88.5, "MRTO": 87.0}, ("medium", 4): {"TO": 64.6, "MR": 86.1, "MRTO": 81.8},
    ("large", 2): {"TO": 67.7, "MR": 85.8, "MRTO": 80.3}, ("large", 4): {"TO": 61.6, "MR": 82.3, "MRTO": 80.7},
}  # fmt: skip


def grasp_candidates(
    scene: Scene,
    rng: np.random.Generator,
    count: int,
    tool_offset: float = 0.151,
    hand: HandFilter | None = None,
    max_draws: int = 60,
    approach: Callable[[FloatArray, int], tuple[FloatArray, float] | None] | None = None,
    standoffs: list[float] | None = None,
) -> tuple[FloatArray, list[GraspedObject], int]:
    """Top-down grasps on the scene's objects: approach tilted up to 20 deg, random roll about it.

    The hand's grasp point is 1-3 cm below an object's top, within half its radius of its axis;
    the TCP stands ``tool_offset`` behind it along the approach (x) axis (TIAGo:
    ``hand_grasping_frame`` is 0.151 m from ``arm_tool_link``). With ``hand``, the generator is a
    grasp planner that knows the true shapes: a draw whose open hand intersects a true solid other
    than the grasped object (the tray's pedestal, bottom and walls, the other objects) is no grasp
    and is drawn again, at most ``max_draws`` draws per grasp. It never sees the placement's voxels.
    ``approach`` (planner v2, protocol v2 only): each draw, before the hand's check, is replaced by
    ``approach(T, i)``'s pose (moved back along its approach axis) or turned down when it returns
    None; each kept grasp's standoff [m] is appended to ``standoffs``. Without it, v1 exactly.

    Returns:
        (K, 4, 4) grasps, K <= count; per grasp the grasped object (its true shape, which only the
        hand may touch); and the number of draws the planner turned down.
    """
    if not scene.objects:
        return np.zeros((0, 4, 4)), [], 0
    objects_of = [grasped_shape(o) for o in scene.objects]
    solids = true_solids(scene) if hand is not None else {}
    grasps: list[FloatArray] = []
    objects: list[GraspedObject] = []
    turned_down = 0
    for _ in range(count * max_draws):
        if len(grasps) == count:
            break
        i = int(rng.integers(len(scene.objects)))
        obj = scene.objects[i]
        offset = rng.uniform(-0.5, 0.5, 2) * obj.radius
        grip = np.array(
            [obj.center[0] + offset[0], obj.center[1] + offset[1], obj.top - rng.uniform(0.01, 0.03)]
        )
        # x (the approach) points down, tilted up to 20 deg towards a random heading; random roll about it
        tilt = rng.uniform(0.0, math.radians(20))
        roll, heading = rng.uniform(-math.pi, math.pi, 2)
        T = pose_from_xyz_rpy([0.0, 0.0, 0.0, roll, math.pi / 2 - tilt, heading])
        T[:3, 3] = grip - tool_offset * T[:3, 0]  # back off along the approach axis
        standoff = 0.0
        if approach is not None:
            moved = approach(T, i)
            if moved is None:
                turned_down += 1
                continue
            T, standoff = moved
        if hand is not None and _hand_touches(
            hand, T, [p for name, p in solids.items() if name != f"object{i}"]
        ):
            turned_down += 1
            continue
        grasps.append(T)
        objects.append(objects_of[i])
        if standoffs is not None:
            standoffs.append(standoff)
    return (np.stack(grasps) if grasps else np.zeros((0, 4, 4))), objects, turned_down


Solid = list[tuple[coal.CollisionGeometry, FloatArray]]


def true_solids(scene: Scene) -> dict[str, Solid]:
    """The tray (pedestal, bottom, walls) and each object as coal shapes with world poses (4, 4).

    Keys: "tray" and "object<i>" (index into ``scene.objects``). The pedestal reaches from z = 0
    to the tray's bottom.
    """
    out: dict[str, Solid] = {}
    box = scene.box
    if box is not None:
        L, W, h = box.size
        e, t = box.elevation, box.wall

        def at(x: float, y: float, z: float, yaw: float = box.yaw) -> FloatArray:
            c, s_ = math.cos(yaw), math.sin(yaw)
            return pose_from_xyz_rpy(
                [box.center[0] + c * x - s_ * y, box.center[1] + s_ * x + c * y, z, 0, 0, yaw]
            )

        out["tray"] = [
            (coal.Box(L, W, e + t), at(0, 0, (e + t) / 2)),
            (coal.Box(t, W, h), at(L / 2 - t / 2, 0, e + h / 2)),
            (coal.Box(t, W, h), at(-L / 2 + t / 2, 0, e + h / 2)),
            (coal.Box(L, t, h), at(0, W / 2 - t / 2, e + h / 2)),
            (coal.Box(L, t, h), at(0, -W / 2 + t / 2, e + h / 2)),
        ]
    for i, o in enumerate(scene.objects):
        geometry = coal.Cylinder(o.size[0] / 2, o.size[2]) if o.shape == "cylinder" else coal.Box(*o.size)
        out[f"object{i}"] = [(geometry, pose_from_xyz_rpy([*o.center, 0.0, 0.0, o.yaw]))]
    return out


def _hand_touches(hand: HandFilter, T_world_tcp: FloatArray, solids: list[Solid]) -> bool:
    """True if the hand's collision geometry at the TCP pose intersects one of the true solids."""
    request = coal.CollisionRequest()
    for geometry, T_tcp_geom in hand.parts:
        T = T_world_tcp @ T_tcp_geom
        placed = coal.Transform3s(T[:3, :3], T[:3, 3])
        for solid in solids:
            for shape, S in solid:
                if coal.collide(geometry, placed, shape, coal.Transform3s(S[:3, :3], S[:3, 3]), request,
                                coal.CollisionResult()):  # fmt: skip
                    return True
    return False


def grasped_shape(obj: SceneObject) -> GraspedObject:
    """The scene object's true shape as the object only the hand may touch."""
    if obj.shape == "cylinder":
        return GraspedObject.cylinder(obj.center, obj.size[0] / 2, obj.size[2])
    return GraspedObject.box(obj.center, obj.size, obj.yaw)


@dataclass
class _Tally:
    """Per strategy: queries, successes, timings [ms] and failure reasons."""

    n: int = 0
    ok: int = 0
    t_rm: list[float] = field(default_factory=list)
    t_a: list[float] = field(default_factory=list)
    t_s: list[float] = field(default_factory=list)
    failures: Counter[str] = field(default_factory=Counter)
    tries_to_success: list[int] = field(default_factory=list)
    on_incline: int = 0
    touched: Counter[str] = field(default_factory=Counter)
    touched_true_scene: Counter[str] = field(default_factory=Counter)

    def merge(self, other: _Tally) -> None:
        """Add another scene's tally to this one."""
        self.n += other.n
        self.ok += other.ok
        self.t_rm += other.t_rm
        self.t_a += other.t_a
        self.t_s += other.t_s
        self.failures.update(other.failures)
        self.tries_to_success += other.tries_to_success
        self.on_incline += other.on_incline
        self.touched.update(other.touched)
        self.touched_true_scene.update(other.touched_true_scene)


@dataclass(frozen=True)
class GroundTruth:
    """IK over a grid of valid base poses on the true surfaces.

    Attributes:
        grid: spacing of base positions [m].
        orientations: base headings per position.
        restarts: IK restarts per pose.
    """

    grid: float = 0.1
    orientations: int = 12
    restarts: int = 4

    def reachable(self, robot: Robot, rmap: ReachabilityMap, scene: Scene, grasp: FloatArray,
                  rng: np.random.Generator) -> bool:  # fmt: skip
        """True if IK reaches ``grasp`` from some valid base pose (closest poses first)."""
        ik = DampedLeastSquaresIK(robot.arm(rmap.info.arm), restarts=self.restarts)
        T_world_base, _ = self.base_poses(robot, rmap, scene, grasp)
        step = 24 * self.orientations
        for start in range(0, len(T_world_base), step):
            _, ok = ik.solve_batch(invert_transforms(T_world_base[start : start + step]) @ grasp, rng)
            if ok.any():
                return True
        return False

    def base_poses(self, robot: Robot, rmap: ReachabilityMap, scene: Scene,
                   grasp: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:  # fmt: skip
        """The valid base poses within the map's reach of ``grasp`` (4, 4), closest positions first.

        Returns:
            (P, 4, 4) world base poses on the true surfaces (each position with its
            ``orientations`` headings in a row) and (P,) the id of the plane each stands on.
        """
        reach = rmap.horizontal_reach
        g = np.arange(-reach, reach + 1e-9, self.grid)
        X, Y = np.meshgrid(grasp[0, 3] + g, grasp[1, 3] + g)
        xy = np.c_[X.ravel(), Y.ravel()]
        xy = xy[np.hypot(xy[:, 0] - grasp[0, 3], xy[:, 1] - grasp[1, 3]) <= reach]
        xy = xy[np.argsort(np.hypot(xy[:, 0] - grasp[0, 3], xy[:, 1] - grasp[1, 3]))]
        ids = scene.surface_id(xy)
        radius = robot.spec.footprint_bounding_radius
        points = shapely.points(xy)
        valid = np.zeros(len(xy), dtype=bool)
        others = [Polygon(p.polygon) for p in scene.planes[1:]]
        if scene.box is not None:
            others.append(Polygon(scene.box.polygon))
        for plane in scene.planes:
            sel = ids == plane.id
            if plane.id == 0:  # the floor: clear of every plane and the box
                ok = np.ones(sel.sum(), dtype=bool)
                for poly in others:
                    ok &= shapely.distance(poly, points[sel]) > radius
            else:  # inside the plane, clear of the box (which may stand on it)
                ok = shapely.distance(Polygon(plane.polygon).exterior, points[sel]) >= radius
                if scene.box is not None:
                    ok &= shapely.distance(Polygon(scene.box.polygon), points[sel]) > radius
            valid[np.flatnonzero(sel)[ok]] = True
        gammas = np.arange(self.orientations) * (2 * math.pi / self.orientations)
        poses = [np.zeros((0, 4, 4))]
        for (x, y), pid in zip(xy[valid], ids[valid], strict=True):
            plane = scene.planes[int(pid)]
            poses.append(plane_base_poses(np.full(len(gammas), x), np.full(len(gammas), y), gammas,
                                          plane.normal, plane.d))  # fmt: skip
        return np.concatenate(poses), np.repeat(ids[valid], len(gammas)).astype(np.int64)


@dataclass(frozen=True)
class ExperimentSettings:
    """The scene and query settings of the OSRM experiment (see :func:`run_osrm_experiment`)."""

    grasps_per_scene: int = 50
    seed: int = HELD_OUT_SEEDS[0]
    tries: int = 100
    box_elevation: float = 0.5
    box_height: float = 0.12
    object_height: tuple[float, float] = (0.15, 0.25)
    extent: tuple[float, float] = (7.0, 7.0)
    box_near: float = 0.3
    collision_cloud: str = "noisy"
    """The cloud ``place`` builds its collision model from (its fine cells near the grasped object,
    its derived clearance): "noisy" (protocols v1, v2: the cloud the terrain is segmented from) or
    "clean" (protocol v3: the noise-free sample the terrain's collision voxels come from, seed
    000's OctoMap). The segmentation is the noisy cloud's in both."""

    def __post_init__(self) -> None:
        if self.collision_cloud not in COLLISION_CLOUDS:
            raise InputError(
                f"collision_cloud must be one of {list(COLLISION_CLOUDS)}, got {self.collision_cloud!r}"
            )


def strategies_for(n_planes: int) -> tuple[str, ...]:
    """Table I (flat) compares the ORM baseline too; Table II only the OSRM strategies."""
    return ("orm", "TO", "MR", "MRTO") if n_planes == 0 else ("TO", "MR", "MRTO")


def experiment_scene(
    s: ExperimentSettings, class_index: int, k: int, classes: tuple[tuple[str, int], ...] = SCENE_CLASSES
) -> tuple[np.random.Generator, Scene, FloatArray, Terrain]:
    """Scene k of a class, deterministic in (seed, class_index, k): (rng, scene, method's cloud, terrain).

    Seed 000 VI adds the noise to the height map: the terrain is segmented from the noisy cloud,
    and its collision voxels (the seed's OctoMap) come from a clean one, a second sensor sample of
    the scene at the same 12.5 mm spacing with no noise (never the true shapes). The cloud returned
    for the method (``place``'s ``points``: its fine collision cells and derived clearance) is the
    noisy one, or with ``s.collision_cloud == "clean"`` that clean sample. The returned generator
    goes on to draw the scene's grasps.
    """
    size_class, n_planes = classes[class_index]
    rng = np.random.default_rng([s.seed, class_index, k])
    settings = SceneSettings(
        size_class="small" if size_class in ("flat", "incline-only") else size_class, n_planes=n_planes,
        box_elevation=s.box_elevation, box_height=s.box_height, object_height=s.object_height,
        extent=s.extent, box_near=s.box_near,
    )  # fmt: skip
    scene = (
        incline_only_scene(settings, rng) if size_class == "incline-only" else generate_scene(settings, rng)
    )
    points = scene.sample_cloud(rng)
    clean = scene.sample_cloud(np.random.default_rng([s.seed, class_index, k, 1]), sigma=0.0)
    terrain = dataclasses.replace(terrain_from_points(points), voxels=VoxelMap.from_points(clean))
    return rng, scene, clean if s.collision_cloud == "clean" else points, terrain


def incline_only_scene(settings: SceneSettings, rng: np.random.Generator) -> Scene:
    """One inclined plane (a ramp from the floor, 3.0-3.4 m square, tilt 5-10 deg) with the tray near its middle.

    The tray's pedestal stands on the incline (its top ``box_elevation`` above the plane there),
    within 0.15 m of the plane's centre: every base pose on the floor is at least 1.2 m from the
    tray's edge, beyond a TIAGo-sized arm's reach, so only poses on the incline reach the objects.
    """
    side = float(rng.uniform(3.0, 3.4))
    yaw = float(rng.uniform(-math.pi, math.pi))
    slope = math.tan(math.radians(float(rng.uniform(5.0, 10.0))))
    uphill = yaw + int(rng.integers(4)) * math.pi / 2  # along a footprint axis: the low edge on the floor
    a, b = slope * math.cos(uphill), slope * math.sin(uphill)
    ex, ey = settings.extent
    floor = Plane(0, "floor", (0.0, 0.0), (ex, ey), 0.0, 0.0, 0.0, 0.0)
    plane = Plane(1, "ramp", (0.0, 0.0), (side, side), yaw, a, b, side / 2 * slope)
    xy = rng.uniform(-0.15, 0.15, 2)
    box_yaw = float(rng.uniform(-math.pi, math.pi))
    elevation = float(plane.z(xy[None])[0]) + settings.box_elevation
    box = Box((float(xy[0]), float(xy[1])), box_yaw, size=(BOX_SIZE[0], BOX_SIZE[1], settings.box_height),
              elevation=elevation)  # fmt: skip
    flat = generate_scene(dataclasses.replace(settings, n_planes=0, box_near=None), rng)
    assert flat.box is not None  # the settings ask for a box
    dz = elevation - flat.box.elevation
    objects = tuple(_moved(o, flat.box, box, dz) for o in flat.objects)
    return Scene(dataclasses.replace(settings, n_planes=1), (floor, plane), box, objects)


def _moved(obj: SceneObject, old: Box, new: Box, dz: float) -> SceneObject:
    """``obj`` carried from the ``old`` box to the ``new`` one (same place in the box frame), ``dz`` up."""
    turn = new.yaw - old.yaw
    c, s_ = math.cos(turn), math.sin(turn)
    dx, dy = obj.center[0] - old.center[0], obj.center[1] - old.center[1]
    x, y = new.center[0] + c * dx - s_ * dy, new.center[1] + s_ * dx + c * dy
    return SceneObject(obj.shape, (x, y, obj.center[2] + dz), obj.yaw + turn, obj.size)


def osrm_scene(
    robot: Robot | str, rmap: ReachabilityMap, class_index: int, k: int, s: ExperimentSettings,
    classes: tuple[tuple[str, int], ...] = SCENE_CLASSES, oracle: AllowedGrasps | None = None,
) -> SceneOutcome:  # fmt: skip
    """One scene of the experiment: grasp candidates, reachable grasps and tallies per strategy.

    Deterministic in (seed, class_index, k), so scenes can run anywhere (``robot`` may be given by
    name or robot-file path, for dask workers). With ``oracle`` (protocol v2), the grasps come from
    planner v2 (:class:`~baseplace_experiments.allowed_grasps.ContactApproach`: each draw moved back
    until the palm meets the object), every counted grasp is also asked whether the true geometry
    allows it at the clearance the method's queries on it report (:func:`query_clearance`; the
    oracle's own generator, so the queries draw as without it, and nothing of the oracle reaches
    the method), and each verified placement's joints are checked on the true shapes with no margin.
    The queries run at the method's default settings in both protocols, on the cloud
    ``s.collision_cloud`` names (:func:`experiment_scene`; the terrain's segmentation is the noisy cloud's).
    """
    robot = Robot(robot) if isinstance(robot, str) else robot
    stats = {name: _Tally() for name in strategies_for(classes[class_index][1])}
    rng, scene, points, terrain = experiment_scene(s, class_index, k, classes)
    hand = HandFilter(robot, rmap.info.arm)
    approach = None if oracle is None else ContactApproach(oracle, scene)
    standoffs: list[float] | None = None if oracle is None else []
    grasps, objects, turned_down = grasp_candidates(scene, rng, s.grasps_per_scene, hand=hand, approach=approach,
                                                    standoffs=standoffs)  # fmt: skip
    truth = GroundTruth()
    reachable = 0
    records: list[GraspRecord] = []
    touch = None if oracle is None else AllowedGrasps(oracle.shapes, 0.0, oracle.grasp_depth, 1)
    for grasp, obj in zip(grasps, objects, strict=True):
        if not truth.reachable(robot, rmap, scene, grasp, rng):
            continue
        reachable += 1
        index = _object_index(scene, obj)
        record = GraspRecord(None, {})
        records.append(record)
        for name, st in stats.items():
            st.n += 1
            record.tries[name] = None
            try:  # stand_on "any": seed 000 counts a placement on every planar region, raised ones too
                res = place(robot, rmap, points, grasp, PlaceSettings(strategy=name, tries=s.tries, stand_on="any",
                                                                      **POSE_ONLY_CHECKS),
                            np.random.default_rng([s.seed, class_index, k, reachable, len(name)]), terrain=terrain,
                            grasped=obj)  # fmt: skip
            except BaseplaceError as exc:  # e.g. no region in reach: a failure of that query
                st.failures[type(exc).__name__] += 1
                continue
            record.clearances[name] = res.clearance
            st.t_rm.append(res.timings_ms["osrm"])
            st.t_a.append(res.timings_ms["request_to_placement"])
            st.failures.update(res.failures)
            for (_, what), n in res.contacts.items():
                st.touched["self" if what.startswith("self") else what] += n
            if res.placements:
                st.ok += 1
                st.t_s.append(res.timings_ms["request_to_placement"])
                st.tries_to_success.append(res.tries)
                record.tries[name] = res.tries
                T = res.placements[0].T_world_base
                st.on_incline += int(scene.surface_id(T[None, :2, 3])[0] >= 1)
                if touch is not None:
                    contact = _placement_contact(touch, scene, index, res.placements[0])
                    if contact is not None:
                        st.touched_true_scene[str(contact)] += 1
        if oracle is not None:  # after the queries: the clearance they report; nothing goes back to them
            record.clearance, record.clearance_from_method = query_clearance(record.clearances)
            T_poses, under = truth.base_poses(robot, rmap, scene, grasp)
            oracle_rng = np.random.default_rng([s.seed, class_index, k, reachable, 99])
            record.allowed = oracle.with_clearance(record.clearance).allowed(scene, grasp, index, T_poses, under,
                                                                             oracle_rng)  # fmt: skip
    return SceneOutcome(len(grasps), reachable, turned_down, terrain.timings_ms["total"], stats, records,
                        standoffs or [])  # fmt: skip


def query_clearance(clearances: dict[str, float]) -> tuple[float, bool]:
    """The clearance [m] the oracle keeps for one grasp: the one every query on it reported.

    Returns (clearance, True) when the queries reported one; (``MIN_CLEARANCE``, False) when none
    returned a result (each raised). Raises RuntimeError when the queries on one grasp report
    different clearances: the grasp's allowed set would depend on the strategy.
    """
    values = set(clearances.values())
    if len(values) > 1:
        raise RuntimeError(f"the queries on one grasp report different clearances: {clearances}")
    return (values.pop(), True) if values else (MIN_CLEARANCE, False)


def _object_index(scene: Scene, obj: GraspedObject) -> int:
    """Index in ``scene.objects`` of the object whose true shape ``obj`` is."""
    return int(np.argmin([np.linalg.norm(np.asarray(o.center) - obj.center) for o in scene.objects]))


def _placement_contact(
    touch: AllowedGrasps, scene: Scene, index: int, placement: Placement
) -> Contact | None:
    """What a verified placement's robot (its base pose and first joints) touches on the true scene, or None."""
    T_world_base = placement.T_world_base
    return touch.touching(placement.joints[0], T_world_base,
                          *scene_solids(scene, index, int(scene.surface_id(T_world_base[None, :2, 3])[0]), touch.grasp_depth))  # fmt: skip


@dataclass
class SceneOutcome:
    """One scene's share of the tables.

    Attributes:
        grasps: grasp candidates from the planner.
        reachable: of those, the ground truth's reachable ones (the queries).
        turned_down: draws the planner turned down (open hand in a true solid).
        segmentation_ms: the scene's segmentation time [ms] (once per scene, not in t_a).
        stats: per strategy, the tally of the queries.
        records: per counted grasp, in order, whether the oracle allows it and each strategy's try.
        standoffs: per grasp, how far [m] planner v2 moved its draw back (protocol v2; empty in v1).
    """

    grasps: int
    reachable: int
    turned_down: int
    segmentation_ms: float
    stats: dict[str, _Tally]
    records: list[GraspRecord] = field(default_factory=list)
    standoffs: list[float] = field(default_factory=list)


@dataclass
class GraspRecord:
    """One counted grasp of a scene.

    Attributes:
        allowed: whether the true geometry allows it at the clearance (None: not asked, protocol v1).
        tries: per strategy, the try at which the first placement was verified (None: none found).
        clearances: per strategy, the clearance [m] its query reported (absent: the query raised).
        clearance: the clearance [m] the oracle kept (protocol v2; see :func:`query_clearance`).
        clearance_from_method: whether ``clearance`` is the queries' (False: no query returned).
    """

    allowed: bool | None
    tries: dict[str, int | None]
    clearances: dict[str, float] = field(default_factory=dict)
    clearance: float | None = None
    clearance_from_method: bool = False


def run_osrm_experiment(
    robot: Robot,
    rmap: ReachabilityMap,
    scenes_per_class: int = 10,
    settings: ExperimentSettings | None = None,
    classes: tuple[tuple[str, int], ...] = SCENE_CLASSES,
    progress: Any = None,
    client: Any = None,
    robot_spec: str | None = None,
) -> dict[str, Any]:
    """Table I and II rows: per scene class and strategy, success and timing over reachable grasps.

    The box stands on a pedestal (``box_elevation``) and is a tray (``box_height``): seed 000's
    ARMAR-6 reaches into a box on the floor; a TIAGo-sized arm (and its 0.15 m hand) needs the
    objects at about table height and walls its forearm can clear for the same task.
    ``object_height`` makes the objects bottle-sized: the open Hey5 fingers reach 9 cm past the
    grasp point, so a top-down grasp on a 4-10 cm object would put them through the box bottom.
    ``extent`` and ``box_near`` crowd the planes around the box, as in seed 000's Fig. 5 scenes,
    so that they take away places to stand on the floor (7 m x 7 m holds four large planes).

    With a dask ``client``, scenes run as tasks on its workers, which load the robot from
    ``robot_spec`` (a built-in name or a robot-file path they can read; default the robot's name);
    the rows are the same as a local run's, timings aside.
    """
    s = settings or ExperimentSettings()
    jobs = [(c, k) for c in range(len(classes)) for k in range(scenes_per_class)]
    if client is None:
        results = []
        for c, k in jobs:
            results.append(osrm_scene(robot, rmap, c, k, s, classes))
            if progress is not None:
                progress(1)
    else:
        from distributed import as_completed

        spec = robot_spec or robot.name
        remote_map = client.scatter(rmap, broadcast=True)
        futures = [client.submit(osrm_scene, spec, remote_map, c, k, s, classes, pure=False) for c, k in jobs]
        for _ in as_completed(futures):
            if progress is not None:
                progress(1)
        results = client.gather(futures)
    rows = []
    for c, (size_class, n_planes) in enumerate(classes):
        mine = [r for (cj, _), r in zip(jobs, results, strict=True) if cj == c]
        for name in strategies_for(n_planes):
            st = _Tally()
            for r in mine:
                st.merge(r.stats[name])
            tries = np.array(st.tries_to_success, dtype=int)
            rows.append({
                "scene": _class_name(size_class, n_planes), "strategy": name, "scenes": scenes_per_class,
                "grasps": sum(r.grasps for r in mine), "planner_turned_down": sum(r.turned_down for r in mine),
                "reachable_grasps": sum(r.reachable for r in mine), "queries": st.n,
                "success_rate": round(100 * st.ok / st.n, 1) if st.n else None,
                "success_rate_at": {str(b): round(100 * int((tries <= b).sum()) / st.n, 1) if st.n else None
                                    for b in BUDGETS},
                "paper_success_rate": PAPER.get((size_class, n_planes), {}).get(name),
                "on_inclined_plane": round(100 * st.on_incline / st.ok, 1) if st.ok else None,
                "t_RM_ms": _mean_std(st.t_rm), "t_a_ms": _mean_std(st.t_a), "t_s_ms": _mean_std(st.t_s),
                "t_a_median_ms": round(float(np.median(st.t_a)), 1) if st.t_a else None,
                "segmentation_ms": _mean_std([r.segmentation_ms for r in mine]),
                "failures": dict(st.failures), "collisions_touching": dict(st.touched),
            })  # fmt: skip
    role = "held-out" if s.seed in HELD_OUT_SEEDS else "dev" if s.seed in DEV_SEEDS else "other"
    return {"rows": rows, "tries": s.tries, "budgets": list(BUDGETS), "seed": s.seed, "seed_role": role,
            "dev_seeds": list(DEV_SEEDS), "held_out_seeds": list(HELD_OUT_SEEDS),
            "settings": dataclasses.asdict(s)}  # fmt: skip


def _class_name(size_class: str, n_planes: int) -> str:
    if n_planes == 0:
        return "flat"
    return "incline-only" if size_class == "incline-only" else f"{size_class} {n_planes} planes"


def _mean_std(values: list[float]) -> list[float] | None:
    return [round(float(np.mean(values)), 1), round(float(np.std(values)), 1)] if values else None
