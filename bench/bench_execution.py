"""Issue 20 item 3: seed 004's table grid executed with a drawn navigation error and the reaching motion.

Protocol (fixed before the held-out run; see ``baseplace_experiments.execution_experiment``):

* Trials: the 12 cells of the table grid, trial k = 0 of each, seed 1 (``table_grid.SEEDS.held_out``;
  seed 0, the development seed, only checked that the script runs). The same scene draws as the
  table-grid experiment.
* Methods: seed 004's baseline pose, seed 004's radial candidates (``CHOSEN`` surface margin),
  baseplace's default (IRM-verified candidates with the reaching-motion check, pickup by motion
  cost) and the robust ranking (the variant ``bench_robustness.py``'s development run chose,
  passed as --pool/--samples/--ik-solutions/--key). Nothing here is tuned.
* Execution: ``DRAWS`` draws of the default navigation error (sigma 3 cm, 2 deg) per trial, the
  same for every method; from each drawn pose, ``ExecutionOracle.execute``: a collision-free IK
  solution of a true-bottle grasp (method's grasp first; stowed + 15 random IK starts; coal on
  the true table and bottle), a reaching motion planned on the robot's voxels of the noisy cloud,
  that path checked on the true scene (<= 3 grasp configurations tried per draw).
* Reported: per method, successful draws / draws, the outcome counts, mean planning time.

Usage: python bench/bench_execution.py --seed 1 [--cells 12] [--pool 6 --samples 64 --ik-solutions 1 --key rate]
"""

from __future__ import annotations

import argparse

from baseplace.placement.robustness import RobustnessSettings
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.model import Robot
from baseplace_experiments.execution_experiment import execution_trial, summarise_execution
from baseplace_experiments.table_grid import RobotShapes
from common import report

DRAWS = 5


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cells", type=int, default=12)
    parser.add_argument("--pool", type=int, default=6)
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--ik-solutions", type=int, default=1)
    parser.add_argument("--key", choices=("rate", "low"), default="rate")
    args = parser.parse_args()
    robot = Robot("tiago")
    rmap = build_map(robot, None, BuildSettings(samples=10_000_000, seed=1))
    shapes = RobotShapes(robot, rmap.info.arm)
    robust = RobustnessSettings(samples=args.samples, ik_solutions=args.ik_solutions, pool=args.pool)
    cells = [(i, j) for j in range(4) for i in range(3)][: args.cells]
    trials = []
    for cell in cells:
        t = execution_trial(robot, rmap, shapes, args.seed, cell, robust, args.key, DRAWS)
        trials.append(t)
        print(cell, {m: (e["success"], e["outcomes"]) for m, e in t["methods"].items()}, flush=True)
    result = {
        "protocol": {"seed": args.seed, "cells": len(cells), "draws": DRAWS, "robust": vars(args),
                     "error_model": "gaussian sigma 0.03 m, 2 deg", "map": "tiago, 1e7 samples, seed 1"},
        "summary": summarise_execution(trials),
        "trials": trials,
    }  # fmt: skip
    report(f"execution_table_grid_seed{args.seed}", result)


if __name__ == "__main__":
    main()
