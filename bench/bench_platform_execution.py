"""Issue 20 item 3: seed 000's platform scenes executed with a drawn navigation error and the reaching motion.

Protocol (written here and in docs/placement.md before the held-out run; the trial itself is
``baseplace_experiments.platform_execution.platform_scene_trials``):

* Scenes (:data:`CLASSES`): two of seed 000's Table II experiment's classes, as
  ``osrm_experiment.experiment_scene`` draws them with ``ExperimentSettings(seed=SEED)`` (tray of
  bottle-sized objects on a 0.5 m pedestal near the planes, 7 m x 7 m): "medium, 4 planes" (the
  robot may stand on the floor, a ramp or a platform) and "incline-only" (the tray in the middle of
  one large ramp: every placement stands on the incline). Scenes k = 0, 1, 2 of each class (development: k = 0).
* Queries: per scene, the first :data:`QUERIES` grasp candidates the ground truth counts as
  reachable (``GroundTruth``: IK from some valid base pose on the true surfaces), in the order the
  grasp planner draws them.
* Methods (``PLATFORM_METHODS``): seed 000's TO, MR and MRTO with its checks (IK + collision at the
  exact pose, no motion check, no robustness; N = 100, M = 1); baseplace's default (MR with the
  reaching-motion check); the robust ranking (the same, pool 10, 64 draws, 1 IK solution per
  draw, ranked by the rate: the variant bench_robustness.py's development run chose). The robot's
  planner, for the default's and the robust ranking's motion check and for the execution, stops
  after 500 state checks (30 s wall cap): the same budget at any load. Nothing is tuned here.
* Execution: per query :data:`DRAWS` draws of the default navigation error (Gaussian sigma 3 cm in
  x and y and 2 deg in heading, redrawn outside Nav2's 0.25 m / 0.25 rad box), drawn in the base's
  frame on its support plane, the same draws for every method. The base rests on the true surface
  under the drawn position. ``PlatformOracle.execute``: the footprint outline must lie wholly on
  one support region of the true scene (the floor clear of every inclined plane and the box; or
  inside one inclined plane, clear of the box), else ``off_region``; a collision-free IK solution
  of the grasp on the true solids (stowed + 15 random starts; FK within 1 mm / 0.01 rad; the floor,
  every inclined plane as a solid block, the tray, the other objects; only the hand may touch the
  grasped object), else ``no_grasp``; the robot's planner on its voxels of the noisy cloud plans the
  reaching motion (``no_motion`` if none), and the path is checked state by state (0.02 rad) on
  the true solids (``motion_collision`` if it touches: nothing in the transit, only the hand on the
  grasped object in the last approach segment). ``no_placement``: the method chose nothing.
* Diagnostic, not in the success rate: each chosen placement is also executed from its own pose
  (no error), so a failure can be told apart as the error's or the placement's.
* Size (from the development run's time, 1 min for 4 queries of which 3 had no placement by any
  method, before any held-out run): 3 scenes per class and 3 queries per scene, 36 queries x 5
  draws = 180 draws per method, about 12-15 minutes on this loaded 2-core machine.
* Seeds: development seed 3100 (1 scene per class, 2 queries: checks that it runs and reads
  why draws fail; nothing is chosen from it); held-out seeds 3101 and 3102, never run by any
  experiment here (bench/results uses 0-8, 100-129, 1000 and 2026).
* Reported: per method, successful draws / draws with a 95 % Wilson interval, outcome counts,
  queries with a placement, mean planning time; load averages at the start and end.

Protocol v2 (issue 27): docs/protocols/platform_execution.md, committed before its held-out run.
The robot solves the grasp's IK itself on its own model from its own starts (v1 handed its planner
the oracle's solution, free on the true solids); held-out seeds 3103 and 3104; results file
``execution_platform_heldout_v2.json`` (v1's file stays as it was).

Usage: python bench/bench_platform_execution.py --split heldout
"""

from __future__ import annotations

import argparse
import itertools
import os

from baseplace.placement.motion import MotionSettings
from baseplace.placement.robustness import RobustnessSettings, wilson_interval
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.model import Robot
from baseplace_experiments.osrm_experiment import SCENE_CLASSES
from baseplace_experiments.platform_execution import (
    PLATFORM_METHODS,
    platform_scene_trials,
    summarise_platform,
)
from baseplace_experiments.results import SeedSplit, fixed_protocol
from baseplace_experiments.table_grid import RobotShapes
from common import report

SEEDS = SeedSplit(dev=(3100,), held_out=(3103, 3104))  # v1: held-out 3101, 3102
PROTOCOL_FILE = "docs/protocols/platform_execution.md"
VERSION = 2
CLASSES = (SCENE_CLASSES.index(("medium", 4)), SCENE_CLASSES.index(("incline-only", 1)))
SCENES = {"dev": 1, "heldout": 3}
QUERIES = {"dev": 2, "heldout": 3}
DRAWS = 5
MOTION = MotionSettings(time_limit=30.0, max_checks=500)
ROBUST = RobustnessSettings(
    samples=64, ik_solutions=1, pool=10, rank="robustness"
)  # bench_robustness dev's choice


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--split", choices=("dev", "heldout"), required=True)
    args = parser.parse_args()
    load_start = os.getloadavg()
    seeds = SEEDS.dev if args.split == "dev" else SEEDS.held_out
    protocol_file = fixed_protocol(PROTOCOL_FILE, "dev" if args.split == "dev" else "held-out")
    robot = Robot("tiago")
    rmap = build_map(robot, None, BuildSettings(samples=10_000_000, seed=1))
    shapes = RobotShapes(robot, rmap.info.arm)
    trials = []
    for seed, c, k in itertools.product(seeds, CLASSES, range(SCENES[args.split])):
        got = platform_scene_trials(
            robot, rmap, shapes, seed, c, k, QUERIES[args.split], DRAWS, MOTION, ROBUST
        )
        trials += got
        for t in got:
            print(
                seed,
                SCENE_CLASSES[c],
                k,
                t["grasp"],
                {m: e["outcomes"] for m, e in t["methods"].items()},
                flush=True,
            )
    summary = summarise_platform(trials)
    for m in PLATFORM_METHODS:
        low, high = wilson_interval(summary[m]["success"], summary[m]["draws"])
        summary[m]["ci95"] = [round(low, 4), round(high, 4)]
    result = {
        "protocol": {"split": args.split, "seeds": list(seeds), "classes": [list(SCENE_CLASSES[c]) for c in CLASSES],
                     "scenes_per_class": SCENES[args.split], "queries_per_scene": QUERIES[args.split], "draws": DRAWS,
                     "planner": {"time_limit": MOTION.time_limit, "max_checks": MOTION.max_checks},
                     "robust": {"pool": ROBUST.pool, "samples": ROBUST.samples, "ik_solutions": ROBUST.ik_solutions,
                                "key": "rate"},
                     "error_model": "gaussian sigma 0.03 m, 2 deg, in the base frame on its plane; tolerances 0.25 m, 0.25 rad",
                     "map": "tiago, 1e7 samples, seed 1",
                     "load_average": {"start": load_start, "end": os.getloadavg()}},
        "queries": len(trials),
        "summary": summary,
        "trials": trials,
    }  # fmt: skip
    report(f"execution_platform_{args.split}_v{VERSION}", result, seeds=SEEDS,
           split="dev" if args.split == "dev" else "held-out", used_seeds=list(seeds),
           protocol_file=protocol_file)  # fmt: skip


if __name__ == "__main__":
    main()
