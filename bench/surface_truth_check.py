"""How much of the surface map's overestimate is the IK truth's own miss rate? (diagnostic, dev poses only)

The validation behind ``bench_surface_map.py`` (SurfaceTruth: 6 orientations x 8 IK restarts per
grid point) can miss points that some orientation reaches, which would make the map's bias look
larger than it is. This re-validates the development poses with R_S > 0 (seed 0, the same draw as
the benchmark) with 4x the orientations and 2x the restarts, and compares both truths with R_S.
Held-out poses are not touched.

Usage: python bench/surface_truth_check.py [--poses 10]
"""

from __future__ import annotations

import argparse

import numpy as np

from baseplace.placement.surface_map import build_surface_map
from baseplace.reachability.build import BuildSettings
from baseplace.reachability.cache import cached_map
from baseplace.robots.model import Robot
from baseplace_experiments.surface_truth import SEEDS, SurfaceTruth, agreement, poses_near_surface, validate
from bench_surface_map import ARM, HEIGHT, ORIENTATIONS, RESOLUTION, TABLE
from common import report


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument(
        "--poses", type=int, default=10, help="dev poses with R_S > 0 to re-validate (default 10)"
    )
    args = parser.parse_args()
    robot = Robot("pr2")
    rmap = cached_map(robot, BuildSettings(), ARM)[0]
    smap = build_surface_map(robot, {ARM: rmap}, TABLE, HEIGHT, RESOLUTION, ORIENTATIONS)
    P = poses_near_surface(smap, 50, np.random.default_rng(SEEDS.dev[0]))
    rs = smap.reachability(P).astype(float)
    P, rs = P[rs > 0][: args.poses], rs[rs > 0][: args.poses]
    rng = np.random.default_rng(SEEDS.dev[0] + 100)
    base, t_base = validate(SurfaceTruth(robot, ARM, smap), P, rng)
    more, t_more = validate(SurfaceTruth(robot, ARM, smap, orientations=24, restarts=16), P, rng)
    report("surface_truth_check", {
        "poses": len(P),
        "truth": {"orientations": 6, "restarts": 8, "seconds_per_pose_median": round(float(np.median(t_base)), 3),
                  "agreement": agreement(rs, base)},
        "more_tries": {"orientations": 24, "restarts": 16,
                       "seconds_per_pose_median": round(float(np.median(t_more)), 3),
                       "agreement": agreement(rs, more)},
        "mean_share_gain": round(float(np.mean(more - base)), 4),
        "per_pose_rs_truth_more": [[round(float(v), 3) for v in row] for row in zip(rs, base, more, strict=True)],
    }, seeds=SEEDS, split="dev", used_seeds=list(SEEDS.dev), protocol=(__doc__ or "").strip())  # fmt: skip


if __name__ == "__main__":
    main()
