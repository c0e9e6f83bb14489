"""Why MR refuses grasps of protocol v2 (Tables I/II) that the oracle allows (development seeds only).

For every counted grasp of protocol v2's dev scenes (seeds 1000-1002; the held-out seeds are
refused) that the oracle (:mod:`baseplace_experiments.allowed_grasps`) allows and MR does not place
within N tries, every candidate MR's verifier rejected for a collision is classified:

* each contact pair (robot geometry, part of the method's model): the part's kind (the exact support
  plane, the fine 1.25 mm denoised cells, the 5 mm edge cells, the 25 mm voxels farther away,
  self-collision), and the geometry's TRUE clearance at that configuration under the oracle's rules
  (coal distance to the true solids of :func:`~baseplace_experiments.allowed_grasps.scene_solids`;
  the grasped object left out for the hand, the rigid hand checked against the object shrunk by the
  grasp depth; the floor and the plane under the base left out for the base's own links);
* (A) every contact's true clearance >= the clearance the method reported: a false refusal of the
  model; (B) some contact's true clearance < the reported clearance (or a self-collision): the
  refusal is right at that configuration (the oracle found another pose or IK branch: MR tries one
  IK solution per base pose, the oracle up to :data:`~baseplace_experiments.allowed_grasps.SOLUTIONS`).

A grasp is (A) when at least one of its candidates is (A) (the model alone refused a configuration
the true scene allows), (B) when it has collision candidates and none is (A), (C) when it has none
(no IK, footprint, the query raised). For the first :data:`DETAILED` collision candidates of each
grasp the touching cells are found (coal distance of each cell's box within the pair's margin) and
put to the true solid nearest their centre, with their signed distance outside its surface.

``--object-height-tolerance`` is a diagnosis, not a setting of the method: the grasped object's
points are taken up to that far above its top (inside its footprint's usual tolerance), so the
share of refusals its own lifted points cause can be measured.

Usage: python bench/osrm_refusals_dev.py --classes flat --out bench/results/osrm_refusals_dev.json
       python bench/osrm_refusals_dev.py --classes flat --collision-cloud clean --out bench/results/osrm_refusals_dev_clean.json

Findings (dev seeds 1000-1002, MR, N = 100; bench/results/osrm_refusals_dev*.json): every allowed
grasp MR refused is (A), every contact an edge (5 mm) cell of the "obstacle" group with the link's
true clearance above the reported one. In the first candidate of 27 of the 28 flat grasps the cells
lie nearest the grasped object itself, 10-24 mm outside it, above its top: its own top points, which
the cloud's 25 mm z-noise lifts past ``OBJECT_TOLERANCE`` (12.5 mm) and which stay as measured in
edge cells because the noise near the object is measured as 0.0 mm (the vertical walls, whose
points the z-noise moves along the wall, make the 20 % quantile of the local fits); the clearance
is then 3 mm.

``--collision-cloud clean`` (protocol v3) hands the method the noise-free 12.5 mm sample the
terrain's voxels come from as its collision cloud (the segmentation stays the noisy cloud's);
``--strategy`` picks TO, MR or MRTO. Findings on the clean cloud are in docs/protocols/osrm_v3.md
(bench/results/osrm_refusals_dev_clean*.json).
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from collections import Counter
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from baseplace.errors import BaseplaceError, InputError
from baseplace.placement.verify import Verifier
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace.world import sensor_resolution
from baseplace.world.environment import Environment, hand_geometry_ids
from baseplace.world.sensor_resolution import EDGE_CELL, FINE
from baseplace_experiments import osrm_experiment
from baseplace_experiments.allowed_grasps import SOLUTIONS, AllowedGrasps, TrueShape, scene_solids
from baseplace_experiments.osrm_experiment import (
    COLLISION_CLOUDS,
    SCENE_CLASSES,
    ExperimentSettings,
    _class_name,
    osrm_scene,
)
from baseplace_experiments.osrm_v2 import GRASPS, SCENES, SEEDS, TRIES
from baseplace_experiments.results import RunClock, write_results
from baseplace_experiments.table_grid import RobotShapes

DETAILED = 3
"""Collision candidates per grasp whose touching cells are found one by one (the costly part)."""


def _tf(T: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(T[:3, :3]), np.asarray(T[:3, 3]))


def distance(g: coal.CollisionGeometry, T: np.ndarray, h: coal.CollisionGeometry, S: np.ndarray) -> float:
    """coal's distance [m] (negative: penetrating)."""
    return float(coal.distance(g, _tf(T), h, _tf(S), coal.DistanceRequest(), coal.DistanceResult()))


def part_kind(part: coal.CollisionGeometry) -> str:
    """The kind of a part of the method's model, from its geometry (with ``--edge-cell`` at 1.25 mm
    the edge cells read as fine cells)."""
    if isinstance(part, coal.OcTree):
        boxes = np.asarray(part.toBoxes())
        size = float(boxes[0, 3]) if len(boxes) else 0.0
        if size <= FINE + 1e-9:
            return "fine 1.25 mm cells"
        if size <= EDGE_CELL + 1e-9:
            return "edge 5 mm cells"
        return f"voxels {size * 1e3:.0f} mm"
    return "support plane" if isinstance(part, coal.Convex) else type(part).__name__


class Truth:
    """The oracle's rules of what each robot geometry must keep clear of, on one grasp's true scene."""

    def __init__(self, oracle: AllowedGrasps, env: Environment, scene: Any, index: int) -> None:
        self.oracle, self.env, self.scene, self.index = oracle, env, scene, index
        self.hand = set(hand_geometry_ids(env.robot, env.geom))
        shapes = oracle.shapes
        names = [o.name for o in shapes.geom.geometryObjects]
        # the oracle's own geometry ids, by name (its model and the method's load the same URDF)
        self.base = {
            k
            for k in range(env._n_robot)
            if names.index(env.geom.geometryObjects[k].name) in oracle.base_links
        }
        self.rigid = {
            k
            for k in range(env._n_robot)
            if names.index(env.geom.geometryObjects[k].name) in oracle.rigid_hand
        }
        self.data = env.model.createData()
        self.gdata = pin.GeometryData(env.geom)
        self._solids: dict[int, tuple[list[TrueShape], list[TrueShape], TrueShape, TrueShape]] = {}

    def solids(self, T: np.ndarray) -> tuple[list[TrueShape], list[TrueShape], TrueShape, TrueShape]:
        under = int(self.scene.surface_id(T[None, :2, 3])[0])
        if under not in self._solids:
            self._solids[under] = scene_solids(self.scene, self.index, under, self.oracle.grasp_depth)
        return self._solids[under]

    def place(self, q_arm: np.ndarray, T: np.ndarray) -> np.ndarray:
        """Poses the robot's geometries; returns the world pose of the robot's root (4, 4)."""
        q = self.env.robot.arm(None).to_pinocchio(q_arm, self.env.robot.q_reference)
        pin.updateGeometryPlacements(self.env.model, self.data, self.env.geom, self.gdata, q)
        return np.asarray(T, dtype=float) @ np.linalg.inv(self.env._T_root_base.homogeneous)

    def clearance(self, k: int, T_world_root: np.ndarray, T: np.ndarray) -> tuple[float, str]:
        """Geometry k's true clearance [m] under the oracle's rules, and the true solid nearest it."""
        g = self.env.geom.geometryObjects[k].geometry
        Tk = T_world_root @ self.gdata.oMg[k].homogeneous
        obstacles, supports, grasped, inner = self.solids(T)
        checks = list(obstacles) + ([] if k in self.base else list(supports))
        if k not in self.hand:
            checks.append(grasped)
        elif k in self.rigid:
            checks.append(inner)  # meeting it (distance < 0) is a contact; at 0 the clearance is moot
        best = (np.inf, "")
        for s in checks:
            d = distance(g, Tk, s.geometry, s.T_world_shape)
            if s is inner:  # only going into it counts; a clearance from it is not asked
                d = np.inf if d >= 0 else d
            best = min(best, (d, s.name))
        return best

    def cells(
        self, k: int, gid: int, margin: float, T_world_root: np.ndarray, T: np.ndarray
    ) -> dict[str, Any]:
        """The cells of part ``gid`` within ``margin`` of geometry ``k``: their true solid, how far outside it."""
        g = self.env.geom.geometryObjects[k].geometry
        Tk = T_world_root @ self.gdata.oMg[k].homogeneous
        part = self.env.geom.geometryObjects[gid].geometry
        if not isinstance(part, coal.OcTree):
            verts = np.array([np.asarray(part.points(i)) for i in range(part.num_points)])
            return {"model_distance_mm": round(distance(g, Tk, part, np.eye(4)) * 1e3, 2),
                    "plane_top_z_m": round(float(verts[:, 2].max()), 4)}  # fmt: skip
        boxes = np.asarray(part.toBoxes())
        centres, size = boxes[:, :3], float(boxes[0, 3])
        g.computeLocalAABB()
        lo, hi = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
        corners = np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )
        world = corners @ Tk[:3, :3].T + Tk[:3, 3]
        pad = margin + size
        near = np.flatnonzero(
            np.all((centres >= world.min(0) - pad) & (centres <= world.max(0) + pad), axis=1)
        )
        box = coal.Box(size, size, size)
        at = np.eye(4)
        d = np.empty(len(near))
        for j, n in enumerate(near):
            at[:3, 3] = centres[n]
            d[j] = distance(g, Tk, box, at)
        touching = near[d < margin]
        out: dict[str, Any] = {"model_distance_mm": round(float(d.min()) * 1e3, 2) if len(d) else None,
                               "touching_cells": len(touching)}  # fmt: skip
        if len(touching):
            obstacles, supports, grasped, _ = self.solids(T)
            solids = [*obstacles, *supports, grasped]
            dot = coal.Sphere(1e-6)
            signed = np.array(
                [
                    [distance(dot, _at(centres[n]), s.geometry, s.T_world_shape) for s in solids]
                    for n in touching
                ]
            )
            nearest = signed.argmin(axis=1)
            by: dict[str, list[float]] = {}
            for row, j in enumerate(nearest):
                by.setdefault(solids[j].name, []).append(float(signed[row, j]))
            out["cells_by_true_solid"] = {name: {"cells": len(v), "outside_mm": [round(min(v) * 1e3, 1),
                                                                                  round(float(np.median(v)) * 1e3, 1),
                                                                                  round(max(v) * 1e3, 1)]}
                                          for name, v in by.items()}  # fmt: skip
            obj = self.scene.objects[self.index]  # where the cells lie relative to the grasped object
            c = centres[touching]
            above = (c[:, 2] - obj.top) * 1e3
            axis = np.hypot(c[:, 0] - obj.center[0], c[:, 1] - obj.center[1]) * 1e3
            out["cells_vs_grasped_object_mm"] = {
                "above_top": [round(float(above.min()), 1), round(float(np.median(above)), 1),
                              round(float(above.max()), 1)],
                "from_axis": [round(float(axis.min()), 1), round(float(axis.max()), 1)],
                "radius": round(obj.radius * 1e3, 1),
            }  # fmt: skip
        return out


def _at(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def classify(truth: Truth, q: np.ndarray, T: np.ndarray, reported: float, detailed: bool) -> dict[str, Any]:
    """One collision-rejected candidate: each contact pair's part kind, the link's true clearance, A or B."""
    env = truth.env
    scene_pairs, self_pairs = env.state_filter(env.robot.arm(None)).touching(q, T)
    T_world_root = truth.place(q, T)
    contacts = []
    for i in self_pairs:
        contacts.append({"link": env._self.pair_links(i)[0] if env._self else "?", "kind": "self-collision",
                         "group": "self", "false": False})  # fmt: skip
    for i in scene_pairs:
        pair = env.geom.collisionPairs[i]
        k, gid = pair.first, pair.second
        margin = env.geom_data.collisionRequests[i].security_margin
        true, nearest = truth.clearance(k, T_world_root, T)
        row = {"link": env._link(k), "geometry": env.geom.geometryObjects[k].name,
               "group": env.geom.geometryObjects[gid].name,
               "kind": part_kind(env.geom.geometryObjects[gid].geometry), "margin_mm": round(margin * 1e3, 2),
               "true_clearance_mm": round(true * 1e3, 2), "nearest_true_solid": nearest,
               "false": bool(true >= reported)}  # fmt: skip
        if detailed:
            row.update(truth.cells(k, gid, margin, T_world_root, T))
        contacts.append(row)
    verdict = "A" if contacts and all(c["false"] for c in contacts) else "B" if contacts else "none"
    return {"class": verdict, "contacts": contacts}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--classes", nargs="+", default=["flat"],
                        help=f"scene classes, of {[_class_name(*c) for c in SCENE_CLASSES]}")  # fmt: skip
    parser.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS.dev))
    parser.add_argument("--scenes", type=int, default=SCENES)
    parser.add_argument("--object-height-tolerance", type=float, default=None,
                        help="diagnosis only: points this far [m] above the grasped object's top, inside its "
                        "footprint's tolerance, are the object's (the library: OBJECT_TOLERANCE, 12.5 mm)")  # fmt: skip
    parser.add_argument("--collision-cloud", choices=COLLISION_CLOUDS, default="noisy",
                        help="the cloud the method's collision model comes from: noisy (protocol v2) or clean "
                        "(protocol v3: the noise-free 12.5 mm sample the terrain's voxels come from)")  # fmt: skip
    parser.add_argument("--strategy", choices=("TO", "MR", "MRTO"), default="MR")
    parser.add_argument("--edge-cell", type=float, default=None,
                        help="diagnosis only: the edge points' cell edge [m] (the library: EDGE_CELL, 5 mm); "
                        "they keep the clearance as before")  # fmt: skip
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    if args.object_height_tolerance is not None:
        _lift_object_tolerance(args.object_height_tolerance)
    if args.edge_cell is not None:
        if not 0 < args.edge_cell <= EDGE_CELL:
            raise InputError(f"--edge-cell must be in (0, {EDGE_CELL}] m, got {args.edge_cell}")
        sensor_resolution.EDGE_CELL = args.edge_cell  # read by sensor_resolution._cells at each call
    names = [_class_name(*c) for c in SCENE_CLASSES]
    if bad := [c for c in args.classes if c not in names]:
        raise InputError(f"unknown class {bad[0]!r}; choose from {names}")
    if not set(args.seeds) <= set(SEEDS.dev):
        raise InputError(
            f"development seeds only ({list(SEEDS.dev)}); held-out {list(SEEDS.held_out)} are spent"
        )
    clock = RunClock()
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    oracle = AllowedGrasps(RobotShapes(robot, rmap.info.arm))

    rejected: list[tuple[Environment, np.ndarray, np.ndarray]] = []
    checked = Verifier.collisions

    def recording(self: Verifier, q: np.ndarray, T: np.ndarray) -> Any:
        out = checked(self, q, T)
        if out is not None:
            rejected.append((self.environment, np.array(q), np.array(T)))
        return out

    queries: list[dict[str, Any]] = []
    real_place = osrm_experiment.place

    def recording_place(*a: Any, **kw: Any) -> Any:
        rejected.clear()
        query: dict[str, Any] = {"grasp": np.array(a[3]), "grasped": kw.get("grasped")}
        queries.append(query)
        try:
            res = real_place(*a, **kw)
        except BaseplaceError as exc:
            query["error"] = type(exc).__name__
            raise
        query.update(result=res, rejected=list(rejected))
        return res

    scenes: list[Any] = []
    real_scene = osrm_experiment.experiment_scene

    def recording_scene(*a: Any, **kw: Any) -> Any:
        out = real_scene(*a, **kw)
        scenes.append(out[1])
        return out

    Verifier.collisions = recording  # type: ignore[method-assign]
    osrm_experiment.experiment_scene = recording_scene  # type: ignore[assignment]
    osrm_experiment.place = recording_place  # type: ignore[assignment]
    strategy = args.strategy
    osrm_experiment.strategies_for = lambda n: (strategy,)  # type: ignore[assignment]
    grasps_out: list[dict[str, Any]] = []
    per_class: dict[str, Counter[str]] = {}
    kinds: dict[str, Counter[str]] = {}
    for cname in args.classes:
        c = names.index(cname)
        tally, kind_tally = per_class.setdefault(cname, Counter()), kinds.setdefault(cname, Counter())
        for seed in args.seeds:
            s = ExperimentSettings(grasps_per_scene=GRASPS, seed=seed, tries=TRIES,
                                   collision_cloud=args.collision_cloud)  # fmt: skip
            for k in range(args.scenes):
                t0 = time.perf_counter()
                queries.clear()
                out = osrm_scene(robot, rmap, c, k, s, SCENE_CLASSES, oracle)
                tally.update({f"placed, touching the true scene: {w}": n
                              for w, n in out.stats[strategy].touched_true_scene.items()})  # fmt: skip
                scene = scenes[-1]
                assert len(queries) == len(out.records)
                for g, (rec, query) in enumerate(zip(out.records, queries, strict=True)):
                    ok = rec.tries[strategy] is not None
                    if ok and rec.clearance is not None:  # the placement on the true shapes, at the clearance
                        near = osrm_experiment._placement_contact(
                            oracle.with_clearance(rec.clearance), scene,
                            osrm_experiment._object_index(scene, query["grasped"]), query["result"].placements[0],
                        )  # fmt: skip
                        if near is not None:
                            tally[f"placed, within the reported clearance of the true scene: {near}"] += 1
                    tally["counted"] += 1
                    tally["allowed"] += bool(rec.allowed)
                    tally["placed"] += ok
                    tally["placed_allowed"] += ok and bool(rec.allowed)
                    if not rec.allowed or ok:
                        continue
                    row = _grasp_row(oracle, scene, query, rec.clearance, kind_tally)
                    row.update(seed=seed, class_name=cname, scene=k, grasp=g)
                    tally[f"class {row['class']}"] += 1
                    grasps_out.append(row)
                    print(
                        seed, cname, k, g, row["class"], row["candidates"], row.get("kinds_false"), flush=True
                    )
                print(
                    f"scene {seed} {cname} {k}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True
                )
    result = {
        "benchmark": "osrm_refusals_dev",
        "strategy": strategy, "collision_cloud": args.collision_cloud, "tries": TRIES, "grasps_per_scene": GRASPS, "scenes_per_seed": args.scenes,
        "classes": args.classes, "object_height_tolerance_m": args.object_height_tolerance, "edge_cell_m": args.edge_cell, "method_ik_solutions_per_pose": 1, "oracle_ik_solutions_per_pose": SOLUTIONS,
        "per_class": {k: dict(v) for k, v in per_class.items()},
        "contacts_by_kind": {k: dict(v.most_common()) for k, v in kinds.items()},
        "grasps": grasps_out,
    }  # fmt: skip
    write_results(args.out, result, clock, seeds=SEEDS, split="dev", used_seeds=args.seeds)
    print(json.dumps({k: result[k] for k in ("per_class", "contacts_by_kind")}, indent=1))
    return 0


def _lift_object_tolerance(metres: float) -> None:
    """Diagnosis: the grasped object's points reach ``metres`` above its top (the library's rule, widened)."""
    real = sensor_resolution._object_points

    def lifted(p: np.ndarray, grasped: Any, *rest: Any) -> Any:
        out = real(p, grasped, *rest)
        if len(p) == 0 or grasped.kind == "points":
            return out
        top = grasped.bottom + grasped.size[2]
        high = (p[:, 2] > top) & (p[:, 2] <= top + metres)
        if high.any():
            high[high] = grasped.footprint_distance(p[high, :2]) <= sensor_resolution.OBJECT_TOLERANCE
        return out | high

    sensor_resolution._object_points = lifted


def _grasp_row(oracle: AllowedGrasps, scene: Any, query: dict[str, Any], reported: float,
               kind_tally: Counter[str]) -> dict[str, Any]:  # fmt: skip
    """One allowed grasp MR did not place: its collision candidates classified."""
    if "error" in query:
        return {"class": "C", "reported_clearance_mm": round(reported * 1e3, 2), "error": query["error"],
                "candidates": 0}  # fmt: skip
    res = query["result"]
    index = osrm_experiment._object_index(scene, query["grasped"])
    out: dict[str, Any] = {"reported_clearance_mm": round(reported * 1e3, 2), "clearance_note": res.clearance_note,
                           "failures": dict(res.failures), "candidates": len(query["rejected"])}  # fmt: skip
    if not query["rejected"]:
        out["class"] = "C"
        return out
    truth = Truth(oracle, query["rejected"][0][0], scene, index)
    verdicts, false_kinds, true_kinds, detail = Counter[str](), Counter[str](), Counter[str](), []
    for n, (_, q, T) in enumerate(query["rejected"]):
        c = classify(truth, q, T, reported, n < DETAILED)
        verdicts[c["class"]] += 1
        for contact in c["contacts"]:
            key = f"{contact['kind']} ({contact['group']})"
            (false_kinds if contact["false"] else true_kinds)[key] += 1
            kind_tally[f"{'false' if contact['false'] else 'true'}: {key}"] += 1
        if n < DETAILED:
            detail.append({"base": [round(float(T[0, 3]), 3), round(float(T[1, 3]), 3)], **c})
    out.update(verdicts=dict(verdicts), kinds_false=dict(false_kinds.most_common()),
               kinds_true=dict(true_kinds.most_common()), detail=detail)  # fmt: skip
    out["class"] = "A" if verdicts["A"] else "B"
    return out


if __name__ == "__main__":
    sys.exit(main())
