"""Batched inverse-reachability lookups per second, against a numpy baseline in the same run.

Usage: python bench/bench_irm.py [--map tiago.rmap] [--n 5e6]
"""

from __future__ import annotations

import argparse

import numpy as np

from baseplace.geometry.poses import BasePose, invert_transforms, parse_pose6
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.storage import load_map
from baseplace.robots.model import Robot
from common import median_time, report


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--map", default=None, help="a map file (default: build 5e6 samples now)")
    parser.add_argument("--n", type=float, default=5e6)
    args = parser.parse_args()
    rmap = (
        load_map(args.map) if args.map else build_map(Robot("tiago"), None, BuildSettings(samples=5_000_000))
    )
    n = int(args.n)
    rng = np.random.default_rng(0)
    bases = BasePose.batch_matrix(np.c_[rng.uniform(-1, 3, n), rng.uniform(-1, 2, n), rng.uniform(-3, 3, n)])
    target = parse_pose6("1.0 0.5 0.9 0 0 0")
    rmap.inverse(target, bases[:10])  # compile and build tables
    t_batch = median_time(lambda: rmap.inverse(target, bases))
    small = bases[:200_000]
    t_numpy = median_time(lambda: rmap.reachability(invert_transforms(small) @ target), repeats=3)
    report(
        "irm_lookup",
        {
            "base_poses": n,
            "seconds_median": round(t_batch, 4),
            "lookups_per_s": round(n / t_batch),
            "numpy_inversion_then_lookup_per_s": round(len(small) / t_numpy),
            "reachable_share": float((rmap.inverse(target, bases) > 0).mean()),
            "target": ">= 5e6 base poses per second",
        },
    )


if __name__ == "__main__":
    main()
