"""What the support slab (issue 20, protocol v3 of bench_execution.py) costs per query.

The default method's query of the executed-grasp experiment (IRM-verified candidates with the
reaching-motion check, ``irm_candidates``) on table-grid scenes of development seed 0, once with
the table's voxels (protocol v2's model) and once with the voxels around the bottle cut down to
the fitted plane (v3's), in the same run, the order alternating per cell. Reported: per model the
median query and model-building time, the median of the per-cell ratios, the candidates found,
the load average (a shared machine: compare the two models, not absolute times). The motion
check's budget is v2/v3's (500 state checks), so both models do comparable work per candidate.

(``bench_robustness.py --part query`` places on seed 000's platform scenes without a grasped
object, and their 25 mm cloud noise fails the plane fit's quality test: the slab never applies
there, so it cannot show the change.)

Usage: python bench/bench_support_plane.py [--cells 4]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from baseplace.placement.irm_candidates import IrmSettings, irm_candidates
from baseplace.placement.motion import MotionSettings
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.model import Robot
from baseplace_experiments.execution_experiment import robot_models
from baseplace_experiments.table_grid import TableGridSettings, object_cloud, table_cloud, table_occupancy
from common import report

SEED = 0  # development seed
MOTION = MotionSettings(time_limit=30.0, max_checks=500)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cells", type=int, default=4, help="cells of the 3 x 4 grid (first N)")
    args = parser.parse_args()
    load_start = os.getloadavg()
    robot = Robot("tiago")
    rmap = build_map(robot, None, BuildSettings(samples=10_000_000, seed=1))
    s = TableGridSettings()
    occupancy = table_occupancy(s)
    rows = []
    for k, cell in enumerate([(i, j) for j in range(4) for i in range(3)][: args.cells]):
        rng = np.random.default_rng([SEED, *cell, 0])  # the scene as in execution_trial
        p_true = s.cell_centre(*cell)
        p_true[:2] += rng.uniform(-s.placement_noise, s.placement_noise, 2)
        p_est = p_true + rng.normal(0.0, s.estimate_sigma, 3)
        clean = np.concatenate([table_cloud(s), object_cloud(p_true, s)])
        seen = clean + rng.normal(0.0, s.cloud_sigma, clean.shape)
        grasps = s.grasps(p_est, s.method_top_below)
        row: dict = {"cell": list(cell)}
        order = ("voxels", "slab") if k % 2 == 0 else ("slab", "voxels")
        for model in order:
            t0 = time.perf_counter()
            env, planner, slab = robot_models(robot, rmap.info.arm, seen, p_est, s, "support", model, MOTION)
            t1 = time.perf_counter()
            pool = irm_candidates(robot, rmap, p_est, grasps, env, occupancy, IrmSettings(),
                                  np.random.default_rng([SEED, *cell, 1]), planner)  # fmt: skip
            t2 = time.perf_counter()
            row[model] = {"build_ms": round((t1 - t0) * 1e3, 1), "query_ms": round((t2 - t1) * 1e3, 1),
                          "motion_ms": round(planner.elapsed_s * 1e3, 1), "found": len(pool),
                          "slab": None if slab is None else slab.to_json()}  # fmt: skip
        row["ratio_slab_voxels"] = round(row["slab"]["query_ms"] / row["voxels"]["query_ms"], 3)
        print(row, flush=True)
        rows.append(row)
    summary = {
        m: {
            "median_query_ms": float(np.median([r[m]["query_ms"] for r in rows])),
            "median_build_ms": float(np.median([r[m]["build_ms"] for r in rows])),
            "found": [r[m]["found"] for r in rows],
        }
        for m in ("voxels", "slab")
    }
    summary["median_ratio_slab_voxels"] = float(np.median([r["ratio_slab_voxels"] for r in rows]))
    report("support_plane_query_time",
           {"seed": SEED, "cells": args.cells, "summary": summary, "rows": rows,
            "load_average": {"start": load_start, "end": os.getloadavg()}},
           split="dev", used_seeds=[SEED])  # fmt: skip


if __name__ == "__main__":
    main()
