"""The reaching-motion check of this checkout against another checkout's, paired in one process (development only).

Between processes this shared machine drifts by as much as a change gains (see
``paired_kernel.py``), so both run here, on the same collision models and inputs. The other
checkout's ``baseplace/placement/motion.py`` and ``baseplace/robots/ik.py`` (``--other``: that
checkout's root, e.g. a ``git worktree`` of the commit to compare with) are loaded as modules of
their own, its motion module wired to its IK; everything else (the environment, the state
filter and its kernel, coal, OMPL) is this checkout's, so a change there is not measured here
(``paired_kernel.py`` pairs the state kernel).

Inputs: the checks of a ``bench_motion_verdicts.py`` results file (development seeds only, as
``profile_motion_stages.py`` replays them), each checkout's ``MotionSettings()`` and the file's
OMPL seed per check. Per check the two take turns ``--turns`` times each (the first turn of each
not counted: caches), and the fastest of the rest is kept. Reported: the medians and means, the
per-check ratio's median and quartiles, how many motions each found in its last turn and how many
checks gave the same answer (no motion in both, or the same path and approach to 1e-9 rad).

Usage: python bench/paired_motion.py --other ../base [--results motion_verdicts_s17_final_a] [--turns 3] [--name paired_motion]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from bench_motion_verdicts import check_seed, row_models
from common import RESULTS, other_module, report
from find_rate import library_commit
from profile_motion_stages import held_out_seeds


def same(a: Any, b: Any) -> bool:
    """Whether two checks' answers agree: both none, or the same path and approach."""
    if a is None or b is None:
        return a is None and b is None
    return bool(
        a.path.shape == b.path.shape
        and a.approach.shape == b.approach.shape
        and np.allclose(a.path, b.path, rtol=0.0, atol=1e-9)
        and np.allclose(a.approach, b.approach, rtol=0.0, atol=1e-9)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--other", type=Path, required=True, help="the other checkout's root")
    parser.add_argument("--results", default="motion_verdicts_s17_final_a", help="bench/results/NAME.json")
    parser.add_argument("--turns", type=int, default=3, help="turns per checkout and check (>= 2)")
    parser.add_argument("--name", default="paired_motion", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    if args.turns < 2:
        parser.error("--turns must be >= 2 (the first turn is not counted)")
    rows = json.loads((RESULTS / f"{args.results}.json").read_text())["checks"]
    if held_out_seeds() & {row["seed"] for row in rows}:
        parser.error(f"{args.results} holds held-out seeds")
    other_ik = other_module(args.other, "robots/ik.py", "other_ik")
    other_motion = other_module(args.other, "placement/motion.py", "other_motion")
    other_motion.DampedLeastSquaresIK = other_ik.DampedLeastSquaresIK  # type: ignore[attr-defined]
    checkers = {
        "this": (MotionChecker, MotionSettings),
        "other": (other_motion.MotionChecker, other_motion.MotionSettings),  # type: ignore[attr-defined]
    }
    robot = Robot("tiago")
    arm = robot.arm(resolve_map(robot, None).rmap.info.arm)
    models: dict[tuple[Any, ...], Any] = {}
    best: dict[str, list[float]] = {"this": [], "other": []}
    found = {"this": 0, "other": 0}
    agree = 0
    for row in rows:
        key = (row["seed"], tuple(row["cell"]), row["grasp"])
        if key not in models:
            models[key] = row_models(robot, arm.name, row)[:2]
        seed = check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        q, T_base, target = (np.array(row[k]) for k in ("q_grasp", "T_world_base", "target"))
        fastest = {"this": np.inf, "other": np.inf}
        answer: dict[str, Any] = {}
        for turn in range(2 * args.turns):
            name = ("this", "other")[turn % 2]
            checker_class, settings_class = checkers[name]
            checker = checker_class(robot, arm, *models[key], settings_class())
            t = time.perf_counter()
            answer[name] = checker.check(q, T_base, target, seed=seed)
            wall = time.perf_counter() - t
            if turn >= 2:
                fastest[name] = min(fastest[name], wall * 1e3)
        for name in best:
            best[name].append(fastest[name])
            found[name] += answer[name] is not None
        agree += same(answer["this"], answer["other"])
    a, b = np.array(best["this"]), np.array(best["other"])
    ratio = a / b
    summary = {
        "checks": len(a),
        "found": found,
        "same_answer": agree,
        "median_ms": {"this": float(np.median(a)), "other": float(np.median(b))},
        "mean_ms": {"this": float(a.mean()), "other": float(b.mean())},
        "ratio_median": float(np.median(ratio)),
        "ratio_quartiles": [float(x) for x in np.quantile(ratio, [0.25, 0.75])],
    }
    print(summary)
    other = library_commit(args.other / "src" / "baseplace")
    result = {"inputs": args.results, "turns": args.turns, "other": other, "library": library_commit()}
    report(args.name, {**result, "summary": summary, "ms": best})


if __name__ == "__main__":
    main()
