"""Sphere queries against a cloud's points: the point index against a k-d tree and coal's octree.

For the real clouds of ../shared/data (PCL's mug table and office, camera frame) and the spheres a
hand's sphere model would pose near them (centres drawn from the points plus 5 cm of Gaussian
offset, radii 1-6 cm, 4 mm clearance) and anywhere in the cloud's box, the time per sphere of:

* ``PointIndex.clear`` (all spheres in one compiled call),
* ``scipy.spatial.cKDTree.query`` (the same answer: nearest distance against the radius),
* coal's collide of one ``coal.Sphere`` with the ``coal.OcTree`` of the cloud's 25 mm voxels (what
  the environment check builds today), one call per sphere, on a subsample of the spheres.

Answers are checked equal between the index and the k-d tree on every sphere. Medians of
``--repeats`` runs; the machine is shared, so ratios within one run are what to compare.

Run: ``python bench/bench_point_index.py [--spheres 20000] [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import coal
import numpy as np
from scipy.spatial import cKDTree

from baseplace.terrain.io import load_cloud
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.point_index import PointIndex
from common import median_time, report

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "pointclouds"
CLOUDS = ("table_scene_mug_stereo_textured.pcd", "office1.pcd")
CLEARANCE = 0.004


def _spheres(P: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    near = P[rng.integers(0, len(P), n // 2)] + rng.normal(0, 0.05, (n // 2, 3))
    lo, hi = P.min(axis=0), P.max(axis=0)
    anywhere = rng.uniform(lo, hi, (n - n // 2, 3))
    return np.vstack([near, anywhere]), rng.uniform(0.01, 0.06, n)


def _coal_clear(tree: coal.OcTree, C: np.ndarray, R: np.ndarray) -> np.ndarray:
    out = np.empty(len(C), dtype=bool)
    identity = coal.Transform3s()
    for s, (c, r) in enumerate(zip(C, R, strict=True)):
        req, res = coal.CollisionRequest(), coal.CollisionResult()
        out[s] = not coal.collide(coal.Sphere(float(r + CLEARANCE)), coal.Transform3s(np.eye(3), c), tree, identity,
                                  req, res)  # fmt: skip
    return out


def bench_cloud(name: str, n: int, repeats: int, rng: np.random.Generator) -> dict[str, Any]:
    P = load_cloud(DATA / name).points
    C, R = _spheres(P, n, rng)
    t = time.perf_counter()
    index = PointIndex(P)
    build_index = time.perf_counter() - t
    index.clear(C[:10], R[:10])  # compiled
    t = time.perf_counter()
    tree = cKDTree(P)
    build_tree = time.perf_counter() - t
    mine = index.clear(C, R, CLEARANCE)
    nearest, _ = tree.query(C, distance_upper_bound=float(R.max() + CLEARANCE))
    agree = int(np.sum(mine == (nearest > R + CLEARANCE)))
    t_index = median_time(lambda: index.clear(C, R, CLEARANCE), repeats)
    t_tree = median_time(lambda: tree.query(C, distance_upper_bound=float(R.max() + CLEARANCE)), repeats)
    voxels = VoxelMap.from_points(P, 0.025)
    octree = coal.makeOctree(np.ascontiguousarray(voxels.centres), voxels.resolution)
    k = min(n, 2000)
    t_coal = median_time(lambda: _coal_clear(octree, C[:k], R[:k]), max(1, repeats // 2))
    coal_clear = _coal_clear(octree, C[:k], R[:k])
    return {
        "cloud": name, "points": len(P), "spheres": n, "agree_with_kd_tree": f"{agree}/{n}",
        "clear_fraction": round(float(mine.mean()), 3),
        "build_s": {"point_index": round(build_index, 3), "kd_tree": round(build_tree, 3)},
        "us_per_sphere": {"point_index": round(t_index / n * 1e6, 3), "kd_tree": round(t_tree / n * 1e6, 3),
                          "coal_octree_25mm": round(t_coal / k * 1e6, 3)},
        "kd_tree_over_index": round(t_tree / t_index, 1),
        "coal_over_index": round((t_coal / k) / (t_index / n), 1),
        "coal_25mm_voxels_refuse_clear_spheres": f"{int(np.sum(mine[:k] & ~coal_clear))}/{int(mine[:k].sum())}",
        "field_resolution_m": round(index.field_h, 4),
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    rows = [bench_cloud(name, args.spheres, args.repeats, rng) for name in CLOUDS]
    report("point_index", {"rows": rows, "clearance_m": CLEARANCE}, used_seeds=[args.seed])


if __name__ == "__main__":
    main()
