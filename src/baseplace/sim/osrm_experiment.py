"""Seed 000's placement experiments (Tables I and II, Fig. 5) on generated scenes.

For each scene class (flat, and {small, medium, large} x {2, 4} planes), scenes are generated
with a box of objects; grasp candidates are top-down poses on the objects. Ground truth, as in
seed 000 VI: a grasp is *reachable* if IK solves it from some base pose on a grid around it that
stands on a true surface with its footprint clear of other planes and the box (the true scene,
not the segmentation, and not the reachability map). For every reachable grasp each strategy
runs Algorithm 2 on the noisy cloud; reported: success %, t_RM (OSRM), t_a (all queries), t_s
(successful queries) and the failure reasons.

The full run's tables are in docs/placement.md (``baseplace experiment osrm``).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import shapely
from shapely.geometry import Polygon

from baseplace.errors import BaseplaceError
from baseplace.geometry.poses import FloatArray, invert_transforms, pose_from_xyz_rpy
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.placement.pipeline import SEED_000_CHECKS, PlaceSettings, place
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.sim.scenes import Scene, SceneSettings, generate_scene
from baseplace.terrain.pipeline import Terrain, terrain_from_points
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import HandFilter

SCENE_CLASSES = (
    ("flat", 0),
    ("small", 2),
    ("small", 4),
    ("medium", 2),
    ("medium", 4),
    ("large", 2),
    ("large", 4),
)
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
    obstacles: VoxelMap | None = None,
) -> tuple[FloatArray, list[tuple[FloatArray, float]]]:
    """Top-down grasps on the scene's objects: approach tilted up to 20 deg, random roll about it.

    The hand's grasp point is 1-3 cm below an object's top, within half its radius of its axis;
    the TCP stands ``tool_offset`` behind it along the approach (x) axis (TIAGo:
    ``hand_grasping_frame`` is 0.151 m from ``arm_tool_link``). With ``hand``, only grasps whose
    hand is clear of the noise-free scene (less the grasped object) are kept, as a grasp planner
    would deliver them; at most ``max_draws`` draws per grasp. The scene is ``obstacles``, the
    voxels the placements are checked against; pass them: a cloud sampled apart voxelizes the box
    rim and the objects' sides a little differently, and a grasp clear of one set of voxels can
    touch the other at every base pose (8 of 500 flat grasps did). Default: a cloud of its own.

    Returns:
        (K, 4, 4) grasps, K <= count, and per grasp the sphere around the grasped object that the
        hand may touch.
    """
    if not scene.objects:
        return np.zeros((0, 4, 4)), []
    spheres_of = [
        (np.asarray(o.center, dtype=float), math.hypot(o.radius, o.size[2] / 2) + 0.03) for o in scene.objects
    ]
    octrees: dict[int, coal.OcTree] = {}
    if hand is not None:
        clean = obstacles or VoxelMap.from_points(scene.sample_cloud(np.random.default_rng(0), sigma=0.0))
        for i, (centre, radius) in enumerate(spheres_of):
            keep = clean.without(np.linalg.norm(clean.centres - centre, axis=1) <= radius)
            octrees[i] = coal.makeOctree(np.ascontiguousarray(keep.centres), keep.resolution)
    grasps: list[FloatArray] = []
    spheres: list[tuple[FloatArray, float]] = []
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
        if hand is not None and not hand.clear(T, octrees[i]):
            continue
        grasps.append(T)
        spheres.append(spheres_of[i])
    return (np.stack(grasps) if grasps else np.zeros((0, 4, 4))), spheres


@dataclass
class _Tally:
    """Per strategy: queries, successes, timings [ms] and failure reasons."""

    n: int = 0
    ok: int = 0
    t_rm: list[float] = field(default_factory=list)
    t_a: list[float] = field(default_factory=list)
    t_s: list[float] = field(default_factory=list)
    failures: Counter[str] = field(default_factory=Counter)

    def merge(self, other: _Tally) -> None:
        """Add another scene's tally to this one."""
        self.n += other.n
        self.ok += other.ok
        self.t_rm += other.t_rm
        self.t_a += other.t_a
        self.t_s += other.t_s
        self.failures.update(other.failures)


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
        arm = robot.arm(rmap.info.arm)
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
            else:
                ok = shapely.distance(Polygon(plane.polygon).exterior, points[sel]) >= radius
            valid[np.flatnonzero(sel)[ok]] = True
        ik = DampedLeastSquaresIK(arm, restarts=self.restarts)
        gammas = np.arange(self.orientations) * (2 * math.pi / self.orientations)
        for start in range(0, int(valid.sum()), 24):
            chunk = xy[valid][start : start + 24]
            chunk_ids = ids[valid][start : start + 24]
            poses = []
            for (x, y), pid in zip(chunk, chunk_ids, strict=True):
                plane = scene.planes[int(pid)]
                poses.append(plane_base_poses(np.full(len(gammas), x), np.full(len(gammas), y), gammas,
                                              plane.normal, plane.d))  # fmt: skip
            T = invert_transforms(np.concatenate(poses)) @ grasp
            _, ok = ik.solve_batch(T, rng)
            if ok.any():
                return True
        return False


@dataclass(frozen=True)
class ExperimentSettings:
    """The scene and query settings of the OSRM experiment (see :func:`run_osrm_experiment`)."""

    grasps_per_scene: int = 50
    seed: int = 0
    tries: int = 100
    box_elevation: float = 0.5
    box_height: float = 0.12
    object_height: tuple[float, float] = (0.15, 0.25)
    extent: tuple[float, float] = (7.0, 7.0)
    box_near: float = 0.3


def strategies_for(n_planes: int) -> tuple[str, ...]:
    """Table I (flat) compares the ORM baseline too; Table II only the OSRM strategies."""
    return ("orm", "TO", "MR", "MRTO") if n_planes == 0 else ("TO", "MR", "MRTO")


def experiment_scene(
    s: ExperimentSettings, class_index: int, k: int, classes: tuple[tuple[str, int], ...] = SCENE_CLASSES
) -> tuple[np.random.Generator, Scene, FloatArray, Terrain]:
    """Scene k of a class, deterministic in (seed, class_index, k): (rng, scene, noisy cloud, terrain).

    Seed 000 VI adds the noise to the height map: the terrain is segmented from the noisy cloud,
    and its collision voxels (the seed's OctoMap) come from a clean one. The returned generator
    goes on to draw the scene's grasps.
    """
    size_class, n_planes = classes[class_index]
    rng = np.random.default_rng([s.seed, class_index, k])
    settings = SceneSettings(
        size_class="small" if size_class == "flat" else size_class, n_planes=n_planes,
        box_elevation=s.box_elevation, box_height=s.box_height, object_height=s.object_height,
        extent=s.extent, box_near=s.box_near,
    )  # fmt: skip
    scene = generate_scene(settings, rng)
    points = scene.sample_cloud(rng)
    clean = VoxelMap.from_points(
        scene.sample_cloud(np.random.default_rng([s.seed, class_index, k, 1]), sigma=0.0)
    )
    return rng, scene, points, dataclasses.replace(terrain_from_points(points), voxels=clean)


def osrm_scene(
    robot: Robot | str, rmap: ReachabilityMap, class_index: int, k: int, s: ExperimentSettings,
    classes: tuple[tuple[str, int], ...] = SCENE_CLASSES,
) -> tuple[int, int, dict[str, _Tally]]:  # fmt: skip
    """One scene of the experiment: (grasp candidates, reachable grasps, tallies per strategy).

    Deterministic in (seed, class_index, k), so scenes can run anywhere (``robot`` may be given by
    name or robot-file path, for dask workers).
    """
    robot = Robot(robot) if isinstance(robot, str) else robot
    stats = {name: _Tally() for name in strategies_for(classes[class_index][1])}
    rng, scene, points, terrain = experiment_scene(s, class_index, k, classes)
    clean = terrain.voxels
    environments: dict[str, Any] = {}
    grasps, spheres = grasp_candidates(scene, rng, s.grasps_per_scene, hand=HandFilter(robot, rmap.info.arm),
                                       obstacles=clean)  # fmt: skip
    truth = GroundTruth()
    reachable = 0
    for grasp, sphere in zip(grasps, spheres, strict=True):
        if not truth.reachable(robot, rmap, scene, grasp, rng):
            continue
        reachable += 1
        for name, st in stats.items():
            st.n += 1
            try:
                res = place(robot, rmap, points, grasp, PlaceSettings(strategy=name, tries=s.tries, **SEED_000_CHECKS),
                            np.random.default_rng([s.seed, class_index, k, reachable, len(name)]), terrain=terrain,
                            environments=environments, ignore=[sphere])  # fmt: skip
            except BaseplaceError as exc:  # e.g. no region in reach: a failure of that query
                st.failures[type(exc).__name__] += 1
                continue
            st.t_rm.append(res.timings_ms["osrm"])
            st.t_a.append(res.timings_ms["query"])
            st.failures.update(res.failures)
            if res.placements:
                st.ok += 1
                st.t_s.append(res.timings_ms["query"])
    return len(grasps), reachable, stats


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
        grasps_total = sum(r[0] for r in mine)
        reachable_total = sum(r[1] for r in mine)
        for name in strategies_for(n_planes):
            st = _Tally()
            for r in mine:
                st.merge(r[2][name])
            rows.append({
                "scene": "flat" if n_planes == 0 else f"{size_class} {n_planes} planes",
                "strategy": name, "scenes": scenes_per_class, "grasps": grasps_total,
                "reachable_grasps": reachable_total,
                "success_rate": round(100 * st.ok / st.n, 1) if st.n else None,
                "paper_success_rate": PAPER.get((size_class, n_planes), {}).get(name),
                "t_RM_ms": _mean_std(st.t_rm), "t_a_ms": _mean_std(st.t_a), "t_s_ms": _mean_std(st.t_s),
                "failures": dict(st.failures),
            })  # fmt: skip
    return {"rows": rows, "tries": s.tries, "seed": s.seed, "settings": dataclasses.asdict(s)}


def _mean_std(values: list[float]) -> list[float] | None:
    return [round(float(np.mean(values)), 1), round(float(np.std(values)), 1)] if values else None
