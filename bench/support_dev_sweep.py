"""Development-seed sweep of the support test's count and threshold (how the defaults were chosen).

On one map, FK poses of 1e4 random configurations (recall) and poses drawn uniformly in reached
cells (precision: the share IK with restarts solves among those each setting calls reachable) come
from a development seed, never the held-out 12345 of ``bench_accuracy.py``. Each (support count,
threshold) reads the same draws; the default threshold 0.8 and count = mean count / 16 were chosen
from such sweeps over TIAGo maps of 5e7, 1e8 and 2e8 samples (docs/maps.md).
Usage: python bench/support_dev_sweep.py --map tiago.rmap [--seed 778] [--poses 8000]
"""

from __future__ import annotations

import argparse

import numpy as np

from baseplace.reachability.certify import poses_in_cells
from baseplace.reachability.storage import load_map
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from common import report

HELD_OUT = 12345


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--map", required=True)
    parser.add_argument("--seed", type=int, default=778, help="a development seed (not 12345)")
    parser.add_argument("--poses", type=int, default=8000)
    args = parser.parse_args()
    if args.seed == HELD_OUT:
        parser.error("--seed 12345 is the held-out seed of bench_accuracy.py; use a development seed")
    robot = Robot("tiago")
    arm = robot.arm()
    rmap = load_map(args.map, robot)
    rng = np.random.default_rng(args.seed)
    held = forward_kinematics(arm, arm.sample(rng, 10_000))
    T = poses_in_cells(rmap.grid, rmap.cells[rng.integers(len(rmap.cells), size=args.poses)], rng)
    _, solved = DampedLeastSquaresIK(arm).solve_batch(T, rng)
    rows = []
    for count in (1, 2, 3, 4, 5, 6):
        for threshold in (0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9):
            m = rmap.with_support(count, threshold)
            kept = m.reachability(T) > 0
            rows.append(
                {
                    "support_count": count,
                    "threshold": threshold,
                    "recall": float((m.reachability(held) > 0).mean()),
                    "precision": round(float(solved[kept].mean()), 4),
                    "n_precision": int(kept.sum()),
                }
            )
            print(rows[-1])
    report(
        f"support_dev_sweep_{rmap.info.samples:.0e}".replace("+", ""),
        {
            "map": {
                "samples": rmap.info.samples,
                "cells_reached": rmap.n_reached,
                "mean_count": float(rmap.counts.mean()),
            },
            "cells_whole_precision": round(float(solved.mean()), 4),
            "rows": rows,
        },
        split="dev",
        used_seeds=[args.seed],
    )


if __name__ == "__main__":
    main()
