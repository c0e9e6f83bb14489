"""The reaching-motion check with this checkout's state kernel against another checkout's, paired in one process (development only).

Between processes this shared machine drifts by as much as a kernel change gains (session 33:
alternated runs of ``profile_motion_stages.py`` read x 0.79 where the paired figure is x 0.93),
so both kernels run here, on the same collision models and inputs. The other checkout's
``baseplace/world/state_kernel.py`` (``--other``: that checkout's root, e.g. a ``git worktree``
of the commit to compare with) is loaded as a module of its own and swapped into
:mod:`baseplace.world.state_filter` for its turns; everything else (the state filter's Python
side, the planner, coal) is this checkout's, so the kernels must share their arguments.

Inputs: the checks of a ``bench_motion_verdicts.py`` results file (development seeds only, as
``profile_motion_stages.py`` replays them), ``MotionSettings()`` and the file's OMPL seed per
check. Per check the two kernels take turns ``--turns`` times each (the first turn of each not
counted: caches), and the fastest of the rest is kept. Reported: the medians and means, the
per-check ratio's median and quartiles, and how many motions each found in its last turn (the
verdicts are coal's, so they should agree).

Usage: python bench/paired_kernel.py --other ../base [--results motion_verdicts_s17_final_a] [--turns 4] [--name paired_kernel]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import baseplace.world.state_filter as state_filter
import baseplace.world.state_kernel as this_kernel
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from bench_motion_verdicts import check_seed, row_models
from common import RESULTS, other_module, report
from find_rate import library_commit
from profile_motion_stages import held_out_seeds

SWAPPED = ("_uncertified_line", "_uncertified_states")
"""The kernel entry points the state filter calls."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--other", type=Path, required=True, help="the other checkout's root")
    parser.add_argument("--results", default="motion_verdicts_s17_final_a", help="bench/results/NAME.json")
    parser.add_argument("--turns", type=int, default=4, help="turns per kernel and check (>= 2)")
    parser.add_argument("--name", default="paired_kernel", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    if args.turns < 2:
        parser.error("--turns must be >= 2 (the first turn is not counted)")
    rows = json.loads((RESULTS / f"{args.results}.json").read_text())["checks"]
    if held_out_seeds() & {row["seed"] for row in rows}:
        parser.error(f"{args.results} holds held-out seeds")
    kernels = {
        "this": this_kernel,
        "other": other_module(args.other, "world/state_kernel.py", "other_state_kernel"),
    }
    robot = Robot("tiago")
    arm = robot.arm(resolve_map(robot, None).rmap.info.arm)
    models: dict[tuple[Any, ...], Any] = {}
    best: dict[str, list[float]] = {"this": [], "other": []}
    found = {"this": 0, "other": 0}
    for row in rows:
        key = (row["seed"], tuple(row["cell"]), row["grasp"])
        if key not in models:
            models[key] = row_models(robot, arm.name, row)[:2]
        seed = check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        q, T_base, target = (np.array(row[k]) for k in ("q_grasp", "T_world_base", "target"))
        fastest = {"this": np.inf, "other": np.inf}
        for turn in range(2 * args.turns):
            name = ("this", "other")[turn % 2]
            for entry in SWAPPED:
                setattr(state_filter, entry, getattr(kernels[name], entry))
            checker = MotionChecker(robot, arm, *models[key], MotionSettings())
            t = time.perf_counter()
            motion = checker.check(q, T_base, target, seed=seed)
            wall = time.perf_counter() - t
            if turn >= 2:
                fastest[name] = min(fastest[name], wall * 1e3)
            if turn >= 2 * args.turns - 2:
                found[name] += motion is not None
        for name in best:
            best[name].append(fastest[name])
    for entry in SWAPPED:
        setattr(state_filter, entry, getattr(this_kernel, entry))
    a, b = np.array(best["this"]), np.array(best["other"])
    ratio = a / b
    summary = {
        "checks": len(a),
        "found": found,
        "median_ms": {"this": float(np.median(a)), "other": float(np.median(b))},
        "mean_ms": {"this": float(a.mean()), "other": float(b.mean())},
        "ratio_median": float(np.median(ratio)),
        "ratio_quartiles": [float(x) for x in np.quantile(ratio, [0.25, 0.75])],
    }
    other = library_commit(args.other / "src" / "baseplace")
    result = {"inputs": args.results, "turns": args.turns, "other": other, "library": library_commit()}
    report(args.name, {**result, "summary": summary, "ms": best})


if __name__ == "__main__":
    main()
