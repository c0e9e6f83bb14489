"""Map accuracy: recall on held-out FK poses and precision against IK ground truth.

Recall: FK poses of 1e4 configurations never used in the build; the share the map calls
reachable. Precision: poses the map calls reachable (a random pose inside a reached cell), solved
by IK with restarts; reported with cells drawn uniformly and weighted by their sample count, and
by count band (boundary cells with one sample are partly unreachable by construction).
The oracle's draws (``default_rng(12345)``) are independent of the build's chunks
(``default_rng([seed, k])``), of a certified map's IK poses (``[seed, CERTIFY_STREAM]``) and of
the quality the map file records (``[seed, MEASURE_STREAM]``).
Usage: python bench/bench_accuracy.py [--map tiago.rmap] [--samples 5e7] [--orientation 0.8]
       [--certify N] [--name accuracy_tiago]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.spatial.transform import Rotation

from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import load_map
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from common import report


def pose_in_cell(rmap: ReachabilityMap, cell: int, rng: np.random.Generator) -> np.ndarray:
    """A uniformly random pose inside a cell (rejection sampling, Haar-uniform rotations)."""
    grid = rmap.grid
    centre = grid.voxel_centre([cell // grid.n_orientations])[0]
    batch = 8 * grid.n_orientations  # a bin holds 1/n_orientations of SO(3): hits ~8 per batch
    while True:
        T = np.zeros((batch, 4, 4))
        T[:, :3, 3] = centre + rng.uniform(-0.5, 0.5, (batch, 3)) * grid.voxel_size
        T[:, :3, :3] = Rotation.random(batch, random_state=rng).as_matrix()
        T[:, 3, 3] = 1.0
        hits = np.flatnonzero(grid.cell_index(T) == cell)
        if len(hits):
            return T[hits[0]]


def precision(rmap, ik, cells, rng) -> float:
    return float(np.mean([ik.solve(pose_in_cell(rmap, int(c), rng), rng) is not None for c in cells]))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--map", default=None)
    parser.add_argument("--samples", type=float, default=5e7)
    parser.add_argument("--n-precision", type=int, default=1000)
    parser.add_argument("--orientation", type=float, default=0.8)
    parser.add_argument("--certify", type=int, default=0)
    parser.add_argument("--name", default="accuracy_tiago")
    parser.add_argument(
        "--min-count", type=int, default=1, help="drop cells with fewer samples (trade-off study)"
    )
    args = parser.parse_args()
    robot = Robot("tiago")
    arm = robot.arm()
    rmap = (
        load_map(args.map, robot)
        if args.map
        else build_map(
            robot,
            None,
            BuildSettings(
                samples=int(args.samples), orientation_resolution=args.orientation, certify=args.certify
            ),
        )
    )
    if args.min_count > 1:
        keep = rmap.counts >= args.min_count
        rmap = ReachabilityMap(rmap.grid, rmap.cells[keep], rmap.counts[keep], rmap.info)
    rng = np.random.default_rng(12345)  # the build used default_rng([seed, k]): disjoint streams
    held_out = forward_kinematics(arm, arm.sample(rng, 10_000))
    recall = float((rmap.reachability(held_out) > 0).mean())
    ik = DampedLeastSquaresIK(arm)
    k = args.n_precision
    uniform = rmap.cells[rng.choice(len(rmap.cells), k, replace=False)]
    weighted = rmap.cells[rng.choice(len(rmap.cells), k, p=rmap.counts / rmap.counts.sum())]
    bands = {}
    for lo, hi in [(1, 1), (2, 4), (5, 19), (20, 10**9)]:
        sel = np.flatnonzero((rmap.counts >= lo) & (rmap.counts <= hi))
        cells = rmap.cells[rng.choice(sel, min(300, len(sel)), replace=False)]
        bands[f"count {lo}-{hi if hi < 10**9 else 'max'}"] = {
            "share_of_cells": round(len(sel) / len(rmap.cells), 3),
            "precision": round(precision(rmap, ik, cells, rng), 3),
        }
    report(
        args.name,
        {
            "map_samples": rmap.info.samples,
            "grid": {
                "voxel_size": rmap.grid.voxel_size,
                "nside": rmap.grid.nside,
                "n_twist": rmap.grid.n_twist,
            },
            "build_time_s": round(rmap.info.build_time_s, 1),
            "certification": json.loads(rmap.info.certification or "{}"),
            "recorded_in_map": json.loads(rmap.info.quality or "{}"),
            "min_count": args.min_count,
            "cells_reached": rmap.n_reached,
            "recall_held_out_fk": recall,
            "precision_cells_uniform": round(precision(rmap, ik, uniform, rng), 3),
            "precision_cells_weighted_by_count": round(precision(rmap, ik, weighted, rng), 3),
            "precision_by_count": bands,
            "target": "recall >= 98%; precision aim >= 90%",
        },
    )


if __name__ == "__main__":
    main()
