"""Do the flat-class grasps that every OSRM strategy fails on have any collision-free placement?

The diagnosis behind the ``obstacles`` argument of ``grasp_candidates``: it runs the grasp filter on
a cloud of its own, as the experiment did before (8 of 500 flat grasps failed under every strategy).
Result (bench/results/osrm_flat_failures.json): none of the 8 has a collision-free placement; the
hand touches a voxel of the placement environment at the grasp itself, which the filter's own
voxels lacked.

Reproduces the flat scenes of ``baseplace experiment osrm`` (class 0, seed 0, ExperimentSettings()
defaults) exactly as :func:`baseplace.sim.osrm_experiment.osrm_scene` builds them (same rng streams,
same ground truth, same ``place`` call and rng), runs the MR strategy and records the grasps it
fails on. For each failed grasp, a collision-checked ground truth: base poses on the true floor on a
dense grid (``--spacing`` m, ``--headings`` headings) within the map's horizontal reach of the grasp,
footprint disc clear of the box (as ``GroundTruth``); IK with ``--restarts`` restarts per pose; for
each pose IK reaches, the batch IK solution is checked with the same whole-robot collision check the
placements go through (``Environment`` built as ``place`` builds it, the grasped object's sphere
ignored), the pose is run through the very ``Verifier`` that ``place`` builds (fresh IK, 80 restarts,
then the collision check), and, where both collide, up to ``--solutions`` more IK solutions from
random seeds are checked. Colliding links are tallied for the first IK solution of each pose.

Prints a summary table and writes bench/results/osrm_flat_failures.json.

Usage: python bench/osrm_flat_failures.py [--map tiago.rmap] [--scenes 10] [--spacing 0.05] [--headings 24]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import shapely
from shapely.geometry import Polygon

from baseplace.demo import cached_map
from baseplace.errors import BaseplaceError
from baseplace.geometry.poses import FloatArray, invert_transforms
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.placement.pipeline import SEED_000_CHECKS, PlaceSettings, _obstacles, place
from baseplace.placement.verify import Candidate, Verifier
from baseplace.reachability.build import BuildSettings
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import load_map
from baseplace.robots.collision import SelfCollision
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Arm, Robot
from baseplace.sim.osrm_experiment import (
    ExperimentSettings,
    GroundTruth,
    experiment_scene,
    grasp_candidates,
)
from baseplace.sim.scenes import Scene
from baseplace.terrain.pipeline import Terrain
from baseplace.terrain.polygons import footprint_inside, footprint_outline
from baseplace.world.environment import Environment, HandFilter

RESULTS = Path(__file__).parent / "results"
CLASS_INDEX = 0  # flat
TOOL_OFFSET = 0.151  # grasp_candidates' default: TCP to grasp point along the approach axis [m]


@dataclasses.dataclass
class SceneRun:
    """One reproduced flat scene and its MR outcomes."""

    k: int
    scene: Scene
    points: FloatArray
    terrain: Terrain
    grasps: FloatArray
    spheres: list[tuple[FloatArray, float]]
    reachable: list[bool]
    outcomes: list[dict[str, Any]]  # per reachable grasp


def reproduce_scene(
    robot: Robot, rmap: ReachabilityMap, k: int, s: ExperimentSettings, strategy: str = "MR"
) -> SceneRun:
    """Scene k of the flat class, built and queried exactly as ``osrm_scene`` does (one strategy)."""
    rng, scene, points, terrain = experiment_scene(s, CLASS_INDEX, k)
    environments: dict[str, Any] = {}
    grasps, spheres = grasp_candidates(scene, rng, s.grasps_per_scene, hand=HandFilter(robot, rmap.info.arm))
    truth = GroundTruth()
    reachable = 0
    flags: list[bool] = []
    outcomes: list[dict[str, Any]] = []
    for i, (grasp, sphere) in enumerate(zip(grasps, spheres, strict=True)):
        ok = truth.reachable(robot, rmap, scene, grasp, rng)
        flags.append(ok)
        if not ok:
            continue
        reachable += 1
        out: dict[str, Any] = {"scene": k, "grasp": i, "reachable_index": reachable}
        try:
            query_rng = np.random.default_rng([s.seed, CLASS_INDEX, k, reachable, len(strategy)])
            query = PlaceSettings(strategy=strategy, tries=s.tries, **SEED_000_CHECKS)
            res = place(robot, rmap, points, grasp, query, query_rng, terrain=terrain,
                        environments=environments, ignore=[sphere])  # fmt: skip
        except BaseplaceError as exc:
            out.update(ok=False, failures={type(exc).__name__: 1}, tries=0)
        else:
            out.update(ok=bool(res.placements), failures=dict(res.failures), tries=res.tries)
        outcomes.append(out)
    return SceneRun(k, scene, points, terrain, grasps, spheres, flags, outcomes)


def grasp_geometry(scene: Scene, grasp: FloatArray, sphere: tuple[FloatArray, float]) -> dict[str, Any]:
    """Where the grasp is relative to the box: TCP and grasp point in the box frame, wall distances."""
    box = scene.box
    assert box is not None
    grip = grasp[:3, 3] + TOOL_OFFSET * grasp[:3, 0]
    c, s_ = math.cos(box.yaw), math.sin(box.yaw)

    def local(p: FloatArray) -> FloatArray:
        d = p[:2] - np.asarray(box.center)
        return np.array([c * d[0] + s_ * d[1], -s_ * d[0] + c * d[1]])

    g_local = local(grip)
    half_in = np.asarray(box.inner_size) / 2
    rim = box.elevation + box.size[2]
    approach = grasp[:3, 0]
    obj = min(scene.objects, key=lambda o: float(np.linalg.norm(np.asarray(o.center) - sphere[0])))
    return {
        "tcp_world": grasp[:3, 3].round(3).tolist(),
        "grip_world": grip.round(3).tolist(),
        "grip_in_box_xy": g_local.round(3).tolist(),
        "tcp_in_box_xy": local(grasp[:3, 3]).round(3).tolist(),
        "box_inner_half_size": half_in.round(3).tolist(),
        "grip_to_inner_wall_xy": (half_in - np.abs(g_local)).round(3).tolist(),
        "grip_to_nearest_outer_edge": round(float(np.min(np.asarray(box.size[:2]) / 2 - np.abs(g_local))), 3),
        "grip_above_rim": round(float(grip[2] - rim), 3),
        "tcp_above_rim": round(float(grasp[2, 3] - rim), 3),
        "approach_tilt_deg": round(math.degrees(math.acos(min(1.0, -approach[2]))), 1),
        "approach_heading_in_box_deg": round(math.degrees(math.atan2(approach[1], approach[0]) - box.yaw), 1),
        "object": {"shape": obj.shape, "size": [round(v, 3) for v in obj.size], "top": round(obj.top, 3)},
        "ignore_sphere_radius": round(float(sphere[1]), 3),
    }


class LinkReport:
    """Names the robot geometries in collision (obstacles and self) for an arm configuration.

    Uses every pair of the environment's geometry model and the (SRDF-pruned) self-collision
    pairs, without stopping at the first contact; diagnostic only, the verdict is the Environment's.
    """

    def __init__(self, robot: Robot, env: Environment) -> None:
        self.robot, self.env = robot, env
        self.self_check = SelfCollision(robot, num_threads=1)
        self.data = robot.model.createData()
        self.self_data = pin.GeometryData(self.self_check.geom)
        self.env_data = pin.GeometryData(env.geom)
        ref = robot.model.createData()
        pin.framesForwardKinematics(robot.model, ref, robot.q_reference)
        self.T_root_base = ref.oMf[robot.model.getFrameId(robot.spec.base_frame)]

    def links(self, arm: Arm, q_arm: FloatArray, T_world_base: FloatArray) -> list[str]:
        """Geometry names touching an obstacle ("name") or another geometry ("a|b")."""
        model = self.robot.model
        q = arm.to_pinocchio(q_arm, self.robot.q_reference)
        names: list[str] = []
        geom = self.self_check.geom
        pin.computeCollisions(model, self.data, geom, self.self_data, q, False)
        for pair, res in zip(geom.collisionPairs, self.self_data.collisionResults, strict=True):
            if res.isCollision():
                a, b = geom.geometryObjects[pair.first].name, geom.geometryObjects[pair.second].name
                names.append(f"self:{a}|{b}")
        env = self.env
        if env.env_id is not None:
            env.geom.geometryObjects[env.env_id].placement = (
                self.T_root_base * pin.SE3(T_world_base).inverse()
            )
            pin.computeCollisions(model, self.data, env.geom, self.env_data, q, False)
            for pair, res in zip(env.geom.collisionPairs, self.env_data.collisionResults, strict=True):
                if res.isCollision():
                    names.append(env.geom.geometryObjects[pair.first].name)
        return names


def floor_positions(
    scene: Scene, grasp: FloatArray, reach: float, spacing: float, radius: float
) -> FloatArray:
    """(P, 2) grid positions within ``reach`` of the grasp, on the floor, footprint disc clear of the box."""
    n = math.floor(reach / spacing)
    g = np.arange(-n, n + 1) * spacing
    X, Y = np.meshgrid(grasp[0, 3] + g, grasp[1, 3] + g)
    xy = np.c_[X.ravel(), Y.ravel()]
    dist = np.hypot(xy[:, 0] - grasp[0, 3], xy[:, 1] - grasp[1, 3])
    xy = xy[dist <= reach]
    xy = xy[scene.surface_id(xy) == 0]
    others = [Polygon(p.polygon) for p in scene.planes[1:]]
    if scene.box is not None:
        others.append(Polygon(scene.box.polygon))
    ok = np.ones(len(xy), dtype=bool)
    for poly in others:
        ok &= shapely.distance(poly, shapely.points(xy)) > radius
    return xy[ok]


def dense_truth(
    robot: Robot,
    rmap: ReachabilityMap,
    run: SceneRun,
    i: int,
    args: argparse.Namespace,
    rng: np.random.Generator,
) -> dict[str, Any]:
    """Collision-checked ground truth for grasp ``i`` of the scene (see the module docstring)."""
    t0 = time.perf_counter()
    grasp, sphere = run.grasps[i], run.spheres[i]
    terrain, seg = run.terrain, run.terrain.segmentation
    # the environment and verifier exactly as place() builds them (strategy MR, ignore=[sphere])
    s = PlaceSettings(strategy="MR", tries=ExperimentSettings().tries, **SEED_000_CHECKS)
    obstacles = _obstacles(terrain, seg, s)
    centres = obstacles.centres
    allowed = np.linalg.norm(centres - np.asarray(sphere[0], dtype=float), axis=1) <= sphere[1]
    env = Environment(robot, obstacles.without(allowed))
    arm = robot.arm(rmap.info.arm)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    polygons = {r.id: terrain.graph.nodes[r.id]["polygon"] for r in seg.regions}
    verifier = Verifier(arm, DampedLeastSquaresIK(arm), env, grasp[None], polygons, outline)
    links = LinkReport(robot, env)

    floor = run.scene.planes[0]
    xy = floor_positions(
        run.scene, grasp, rmap.horizontal_reach, args.spacing, robot.spec.footprint_bounding_radius
    )
    gammas = np.arange(args.headings) * (2 * math.pi / args.headings)
    X = np.repeat(xy[:, 0], len(gammas))
    Y = np.repeat(xy[:, 1], len(gammas))
    G = np.tile(gammas, len(xy))
    T_bases = plane_base_poses(X, Y, G, floor.normal, floor.d)
    ik = DampedLeastSquaresIK(arm, restarts=args.restarts)
    q_all = np.zeros((len(T_bases), arm.n_joints))
    reached = np.zeros(len(T_bases), dtype=bool)
    for start in range(0, len(T_bases), 2048):
        T = invert_transforms(T_bases[start : start + 2048]) @ grasp
        q, ok = ik.solve_batch(T, rng)
        q_all[start : start + 2048], reached[start : start + 2048] = q, ok
    t_ik = time.perf_counter() - t0

    region_of = seg.region_at(xy)
    free_first = free_verified = free_any = footprint_ok = in_scene = 0
    radius = robot.spec.footprint_bounding_radius
    half_extent = np.asarray(run.scene.settings.extent) / 2
    link_counts: Counter[str] = Counter()
    verifier_no_ik = 0
    examples: list[dict[str, Any]] = []
    free_positions: set[int] = set()
    for p in np.flatnonzero(reached):
        T_wb = T_bases[p]
        pos = int(p) // len(gammas)
        first_free = not env.colliding_arm(arm, q_all[p], T_wb)
        if not first_free:
            link_counts.update(set(links.links(arm, q_all[p], T_wb)))
        n_no_ik = verifier.failures["no_ik"]
        verified = verifier.check(Candidate(T_wb, -1, 0.0), rng) is not None
        verifier_no_ik += verifier.failures["no_ik"] - n_no_ik
        anyfree = first_free or verified
        tried = 0
        while not anyfree and tried < args.solutions:
            tried += 1
            q = verifier.ik.solve(
                invert_transforms(T_wb) @ grasp, rng, q_seed=rng.uniform(arm.lower, arm.upper)
            )
            if q is not None and not env.colliding_arm(arm, q, T_wb):
                anyfree = True
        free_first += first_free
        free_verified += verified
        free_any += anyfree
        if anyfree:
            free_positions.add(pos)
            region = int(region_of[pos])
            inside = region >= 0 and footprint_inside(polygons[region], outline, T_wb)
            footprint_ok += inside
            in_scene += bool(np.all(np.abs(xy[pos]) + radius <= half_extent))
            if len(examples) < 5:
                examples.append(
                    {
                        "xy": xy[pos].round(3).tolist(),
                        "heading_deg": round(math.degrees(G[p]), 1),
                        "region": region,
                        "footprint_inside_region": bool(inside),
                        "first_solution_free": bool(first_free),
                        "verifier_accepts": bool(verified),
                    }
                )
    d = np.hypot(xy[:, 0] - grasp[0, 3], xy[:, 1] - grasp[1, 3])
    reached_positions = np.unique(np.flatnonzero(reached) // len(gammas))
    nearest_reachable = round(float(d[reached_positions].min()), 3) if len(reached_positions) else None
    return {
        "positions": len(xy),
        "poses": len(T_bases),
        "ik_reachable_poses": int(reached.sum()),
        "ik_reachable_positions": len(reached_positions),
        "free_first_ik_solution": int(free_first),
        "verifier_accepts": int(free_verified),
        "verifier_no_ik_on_ik_reachable": int(verifier_no_ik),
        "free_any_ik_solution": int(free_any),
        "free_positions": len(free_positions),
        "free_and_footprint_inside_segmented_region": int(footprint_ok),
        "free_and_footprint_inside_scene_extent": int(in_scene),
        "nearest_position_m": round(float(d.min()), 3) if len(d) else None,
        "nearest_reachable_position_m": nearest_reachable,
        "colliding_geometries_first_solution": dict(link_counts.most_common()),
        "examples_free": examples,
        "seconds": {"ik": round(t_ik, 1), "total": round(time.perf_counter() - t0, 1)},
    }


def main() -> None:
    """Reproduce the flat scenes, find MR failures, and run the dense collision-checked truth on them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    parser.add_argument("--scenes", type=int, default=10, help="flat scenes k = 0..N-1 (default 10)")
    parser.add_argument("--spacing", type=float, default=0.05, help="grid spacing [m] (default 0.05)")
    parser.add_argument("--headings", type=int, default=24, help="headings per position (default 24)")
    parser.add_argument("--restarts", type=int, default=8, help="IK restarts per grid pose (default 8)")
    parser.add_argument(
        "--solutions",
        type=int,
        default=8,
        help="extra IK solutions tried where the first two collide (default 8)",
    )
    parser.add_argument("--out", default=str(RESULTS / "osrm_flat_failures.json"))
    args = parser.parse_args()
    robot = Robot("tiago")
    rmap = load_map(args.map, robot) if args.map else cached_map(robot, BuildSettings())[0]
    s = ExperimentSettings()
    t0 = time.perf_counter()
    runs: list[SceneRun] = []
    failed: list[tuple[int, int]] = []
    n_queries = n_ok = 0
    for k in range(args.scenes):
        run = reproduce_scene(robot, rmap, k, s)
        runs.append(run)
        n_queries += len(run.outcomes)
        n_ok += sum(o["ok"] for o in run.outcomes)
        failed += [(k, o["grasp"]) for o in run.outcomes if not o["ok"]]
        fails = [o["grasp"] for o in run.outcomes if not o["ok"]]
        print(
            f"scene {k}: {len(run.grasps)} grasps, {sum(run.reachable)} reachable, "
            f"MR failures {fails} ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    rate = 100 * n_ok / n_queries if n_queries else float("nan")
    print(f"MR: {n_ok}/{n_queries} ({rate:.1f} %), {len(failed)} failures", flush=True)
    rows: list[dict[str, Any]] = []
    for k, i in failed:
        run = runs[k]
        outcome = next(o for o in run.outcomes if o["grasp"] == i)
        truth = dense_truth(robot, rmap, run, i, args, np.random.default_rng([s.seed, CLASS_INDEX, k, i, 7]))
        geometry = grasp_geometry(run.scene, run.grasps[i], run.spheres[i])
        row: dict[str, Any] = {
            "scene": k,
            "grasp": i,
            "mr": outcome,
            "geometry": geometry,
            "dense_truth": truth,
        }
        rows.append(row)
        print(
            f"scene {k} grasp {i}: IK poses {truth['ik_reachable_poses']}, free (first IK) "
            f"{truth['free_first_ik_solution']}, verifier accepts {truth['verifier_accepts']}, "
            f"free (any IK) {truth['free_any_ik_solution']} ({truth['seconds']['total']:.0f} s)",
            flush=True,
        )
    print()
    print(
        f"{'scene':>5} {'grasp':>5} {'MR fail reasons':<28} {'IK poses':>8} {'free1':>6} {'verif':>6} "
        f"{'freeAny':>7} {'inRegion':>8} {'grip->wall xy':>14} {'grip-rim':>8}  top colliding"
    )
    for r in rows:
        t, g = r["dense_truth"], r["geometry"]
        reasons = ",".join(f"{a}:{b}" for a, b in r["mr"]["failures"].items())
        top = ", ".join(list(t["colliding_geometries_first_solution"])[:3])
        wall = "/".join(f"{v:.2f}" for v in g["grip_to_inner_wall_xy"])
        print(
            f"{r['scene']:>5} {r['grasp']:>5} {reasons:<28} {t['ik_reachable_poses']:>8} "
            f"{t['free_first_ik_solution']:>6} {t['verifier_accepts']:>6} {t['free_any_ik_solution']:>7} "
            f"{t['free_and_footprint_inside_segmented_region']:>8} {wall:>14} "
            f"{g['grip_above_rim']:>8.3f}  {top}"
        )
    result = {
        "benchmark": "osrm_flat_failures",
        "settings": {
            **dataclasses.asdict(s),
            "class_index": CLASS_INDEX,
            "strategy": "MR",
            "spacing": args.spacing,
            "headings": args.headings,
            "ik_restarts": args.restarts,
            "extra_solutions": args.solutions,
            "map_horizontal_reach": round(rmap.horizontal_reach, 3),
            "footprint_bounding_radius": robot.spec.footprint_bounding_radius,
        },
        "scenes": args.scenes,
        "mr_queries": n_queries,
        "mr_successes": n_ok,
        "mr_success_rate": round(rate, 1),
        "failed": [list(f) for f in failed],
        "rows": rows,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
