"""Why ``place`` refuses dev scenes of bench/find_rate.py that the oracle solves (development data only).

For every scene of the given dev seeds (25000-25059; the held-out seeds are refused) where the
oracle of ``find_rate.py`` finds a placement and ``place`` does not, the first rejected candidates'
collisions are classified: which robot link touched which part of ``place``'s model (the exact
support plane; the cells of the obstacle group, of the kind the model made them (:func:`cell_kind`:
smoothed or raw 1.25 mm point cells, 5 mm raw cells, 25 mm voxels), each put to the true shape
nearest to it: a neighbour, the table, the grasped bottle's own points, the floor), the link's TRUE clearance at
that configuration (coal distance to the true shapes of the scene, the grasped bottle left out for
the hand, which may touch it), and the model's clearance there (the security margin of the pair,
coal's distance to the part, the plane's height above the true table top). A refusal with no
collision (the reaching motion) is listed with its failure counts.

Usage: python bench/find_rate_refusals.py --from a.json [b.json ...] --out bench/results/x.json [--seeds 25038]
(``--from``: results files of find_rate.py / find_rate_dev_extra.py on dev seeds: their oracle
verdicts are reused, their scenes must match the generator's.)
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.errors import InputError
from baseplace.placement.verify import Verifier
from baseplace.robots.model import Robot
from baseplace.world.environment import Environment, hand_geometry_ids
from baseplace.world.neighbour_shapes import FittedShape
from baseplace.world.sensor_resolution import Part, RawCells, SupportPlane, SurfaceCells, is_fine
from baseplace_experiments.results import RunClock, write_results
from find_rate import SEEDS, Oracle, Scene, make_scene, refusal_reason, run_place, scenes_by_seed

CANDIDATES = 3
"""Rejected candidates classified per scene (the hand's contacts repeat for every base pose)."""


def _tf(T: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(T[:3, :3]), np.asarray(T[:3, 3]))


def _at(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def true_distance(
    geometry: coal.CollisionGeometry, T: np.ndarray, solid_geometry: Any, solid_T: np.ndarray
) -> float:
    """coal's distance [m] between a robot geometry and a true shape (negative: penetrating, as coal reports)."""
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    return float(coal.distance(geometry, _tf(T), solid_geometry, _tf(solid_T), request, result))


def nearest_shape(points: np.ndarray, scene: Scene) -> tuple[list[str], np.ndarray]:
    """Per point (N, 3): the true shape nearest it and its signed distance to that shape's surface [m]."""
    lx, ly, h = scene.table
    q = np.abs(points) - [lx / 2, ly / 2, 0.0]
    q[:, 2] = np.abs(points[:, 2] - h / 2) - h / 2
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    table = outside + np.minimum(q.max(axis=1), 0.0)
    names, dists = ["table", "floor"], [table, points[:, 2]]
    cylinders = [("bottle (own points)", scene.bottle)] + [
        (f"neighbour {k}", n) for k, n in enumerate(scene.neighbours)
    ]
    for name, (x, y, r, hb) in cylinders:
        radial = np.hypot(points[:, 0] - x, points[:, 1] - y) - r
        axial = np.abs(points[:, 2] - (h + hb / 2)) - hb / 2
        d = np.hypot(np.maximum(radial, 0), np.maximum(axial, 0)) + np.minimum(np.maximum(radial, axial), 0)
        names.append(name)
        dists.append(d)
    D = np.stack(dists)
    best = np.argmin(D, axis=0)
    return [names[k] for k in best], D[best, np.arange(len(points))]


def cell_kind(part: Part | None) -> str:
    """What the model's part holds, as the model marks it (:mod:`baseplace.world.sensor_resolution`).

    ``smoothed``: points put onto their local surface (:class:`SurfaceCells`); ``raw``: points kept as
    measured, in :data:`~baseplace.world.sensor_resolution.FINE` cells where the noise margin covers
    their sampling (:class:`RawCells`), else in coarser cells (:data:`~baseplace.world.sensor_resolution.EDGE_CELL`);
    ``voxels``: coarse voxels, no margin. The cell edge follows [mm]. ``fitted cylinder`` or
    ``fitted box``: a neighbour fitted as a whole shape (:class:`FittedShape`).
    """
    if isinstance(part, FittedShape):
        return f"fitted {part.kind}"
    if part is None or isinstance(part, SupportPlane):
        return "support plane" if part is not None else "unknown"
    size = f"{part.resolution * 1e3:g} mm"
    if isinstance(part, SurfaceCells):
        return f"smoothed {size}"
    if isinstance(part, RawCells) or is_fine(part):
        return f"raw {size}"
    return f"voxels {size}"


def classify_pair(env: Environment, k: int, gid: int, margin: float, T_world_root: np.ndarray,
                  scene: Scene) -> dict[str, Any]:  # fmt: skip
    """What part of the model the robot geometry ``k`` touched in the part ``gid``, and how far its cells lie
    from the true shapes."""
    g = env.geom.geometryObjects[k].geometry
    Tk = T_world_root @ env.geom_data.oMg[k].homogeneous
    part = env.geom.geometryObjects[gid].geometry
    out: dict[str, Any] = {"group": env.geom.geometryObjects[gid].name, "cells": cell_kind(env.parts.get(gid)),
                           "margin_mm": round(margin * 1e3, 2)}  # fmt: skip
    if isinstance(part, coal.OcTree):
        boxes = np.asarray(part.toBoxes())
        centres, size = boxes[:, :3], float(boxes[0, 3]) if len(boxes) else 0.0
        out["cell_mm"] = round(size * 1e3, 3)
        g.computeLocalAABB()
        reach = float(g.aabb_radius) + margin + size
        centre = Tk[:3, :3] @ np.asarray(g.aabb_center) + Tk[:3, 3]
        near = np.flatnonzero(np.linalg.norm(centres - centre, axis=1) <= reach)
        box = coal.Box(size, size, size)
        d = np.array([true_distance(g, Tk, box, _at(centres[n])) for n in near])
        touching = near[d < margin]
        out["model_distance_mm"] = round(float(d.min()) * 1e3, 2) if len(d) else None
        if len(touching):
            names, signed = nearest_shape(centres[touching], scene)
            by = Counter(names)
            out["touching_cells"] = dict(by)
            out["cells_outside_true_surface_mm"] = {
                name: [round(float(np.min(signed[[n == name for n in names]])) * 1e3, 1),
                       round(float(np.max(signed[[n == name for n in names]])) * 1e3, 1)]
                for name in by
            }  # fmt: skip
            tops = {f"neighbour {k}": scene.table[2] + n[3] for k, n in enumerate(scene.neighbours)}
            z = centres[touching, 2]
            out["cells_below_top_mm"] = {  # a rim's points lie within about 2 cm of its top
                name: [round(float(np.min(tops[name] - z[[n == name for n in names]])) * 1e3, 1),
                       round(float(np.max(tops[name] - z[[n == name for n in names]])) * 1e3, 1)]
                for name in by if name in tops
            }  # fmt: skip
    elif isinstance(env.parts.get(gid), FittedShape):  # a neighbour fitted as a whole shape: an exact convex
        out["model_distance_mm"] = round(true_distance(g, Tk, part, np.eye(4)) * 1e3, 2)
    else:  # the exact support plane: a convex prism whose top face is the fitted plane
        out["model_distance_mm"] = round(true_distance(g, Tk, part, np.eye(4)) * 1e3, 2)
        verts = np.array([np.asarray(part.points(i)) for i in range(part.num_points)])
        top = verts[:, 2].max()
        out["plane_top_above_true_table_mm"] = round(float(top - scene.table[2]) * 1e3, 2)
    return out


def link_clearance(
    env: Environment, k: int, T_world_root: np.ndarray, scene: Scene, hand: set[int]
) -> dict[str, Any]:
    """The true clearance [mm] of the robot geometry ``k`` to each true shape (the bottle too, for the record)."""
    g = env.geom.geometryObjects[k].geometry
    Tk = T_world_root @ env.geom_data.oMg[k].homogeneous
    obstacles, bottle, floor = scene.solids()
    out = {}
    for s in [*obstacles, bottle, floor]:
        out[s.name] = round(true_distance(g, Tk, s.geometry, s.T) * 1e3, 2)
    counting = {n: v for n, v in out.items() if not (n == "bottle" and k in hand)}
    return {"to_shapes_mm": out, "true_clearance_mm": min(counting.values())}


def analyse(env: Environment, q: np.ndarray, T: np.ndarray, scene: Scene) -> list[dict[str, Any]]:
    """Every collision pair of the robot at arm joints ``q`` and base pose ``T``, classified."""
    arm = env.robot.arm()
    # coal on every scene pair at this state: contacts_arm asks coal only about the pairs the state
    # filter leaves, so the other pairs' results would be those of an earlier state
    env._place_obstacles(T)
    pin.computeCollisions(
        env.model, env.data, env.geom, env.geom_data, arm.to_pinocchio(q, env.robot.q_reference), False
    )
    T_world_root = np.asarray(T, dtype=float) @ np.linalg.inv(env._T_root_base.homogeneous)
    hand = set(hand_geometry_ids(env.robot, env.geom))
    rows = []
    for n, (pair, res) in enumerate(
        zip(env.geom.collisionPairs, env.geom_data.collisionResults, strict=True)
    ):
        if not res.isCollision():
            continue
        margin = env.geom_data.collisionRequests[n].security_margin
        row = {"link": env._link(pair.first), "geometry": env.geom.geometryObjects[pair.first].name,
               **classify_pair(env, pair.first, pair.second, margin, T_world_root, scene),
               **link_clearance(env, pair.first, T_world_root, scene, hand)}  # fmt: skip
        rows.append(row)
    return rows


def cause(rows: list[dict[str, Any]]) -> str:
    """One key per scene: what the model had that the true scene has not (the first unjustified contact)."""
    for r in rows:
        if r["true_clearance_mm"] > r["margin_mm"] or r["true_clearance_mm"] > 0:
            part = (
                "support plane"
                if "plane_top_above_true_table_mm" in r
                else r["cells"]
                if r["cells"].startswith("fitted")
                else f"{r['cells']}: " + "+".join(sorted(r.get("touching_cells", {})))
            )
            return f"{r['link']} on {r['group']} ({part}): true clearance {r['true_clearance_mm']:.0f} mm"
    return "true contact"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="sources", nargs="+", required=True, help="dev results files")
    parser.add_argument("--out", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=None, help="only these scenes of the sources")
    args = parser.parse_args(argv)
    clock = RunClock()
    verdicts = scenes_by_seed(args.sources)
    if any(seed >= min(SEEDS.held_out) for seed in verdicts):
        raise InputError("development seeds only: a source file holds held-out scenes")
    if args.seeds is not None:
        missing = sorted(set(args.seeds) - set(verdicts))
        if missing:
            raise InputError(f"seeds {missing} are not in the source files")
        verdicts = {seed: verdicts[seed] for seed in args.seeds}
    seen: list[tuple[Environment, np.ndarray, np.ndarray]] = []
    checked = Verifier.collisions

    def recording(self: Verifier, q: np.ndarray, T: np.ndarray) -> Any:
        out = checked(self, q, T)
        if out is not None and len(seen) < CANDIDATES:
            seen.append((self.environment, np.array(q), np.array(T)))
        return out

    Verifier.collisions = recording  # type: ignore[method-assign]
    robot = Robot("tiago")
    oracle = Oracle(robot)
    rows, causes = [], Counter[str]()
    for seed in sorted(verdicts):
        earlier = verdicts[seed]
        scene = make_scene(seed)
        if earlier["scene"] != scene.record():
            raise InputError(f"scene {seed} differs from its source file's")
        if not earlier["oracle"]["found"]:
            continue
        seen.clear()
        method = run_place(scene, oracle)
        if method["found"]:
            rows.append({"seed": seed, "kind": scene.kind, "found": True})
            continue
        candidates = [{"base": [round(float(T[0, 3]), 3), round(float(T[1, 3]), 3)],
                       "contacts": analyse(env, q, T, scene)} for env, q, T in seen]  # fmt: skip
        key = cause(candidates[0]["contacts"]) if candidates else refusal_reason(method)
        short = key.split(": true clearance")[0]
        causes[short] += 1
        rows.append({"seed": seed, "kind": scene.kind, "found": False, "refusal": refusal_reason(method),
                     "failures": method["failures"], "cause": key, "candidates": candidates})  # fmt: skip
        print(seed, scene.kind, key, flush=True)
    hand_method = sorted({robot.model.frames[oracle.geom.geometryObjects[k].parentFrame].name
                          for k in hand_geometry_ids(robot, oracle.geom)})  # fmt: skip
    result = {
        "benchmark": "find_rate_dev_refusals",
        "sources": [Path(p).name for p in args.sources],
        "hand_links_oracle_equal_method": hand_method == oracle.hand_links,
        "solvable": sum(1 for s in verdicts.values() if s["oracle"]["found"]),
        "found": sum(1 for r in rows if r["found"]),
        "causes": dict(causes.most_common()),
        "scenes": rows,
    }
    write_results(args.out, result, clock, used_seeds=sorted(verdicts))
    print(
        json.dumps(
            {k: result[k] for k in ("solvable", "found", "causes", "hand_links_oracle_equal_method")},
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
