"""The whole-line check's calls of the 72 dev motion checks, replayed with and without certificates ahead (development only).

Wall times of ``bench_motion_verdicts.py`` on this shared machine move 2x with its load, more than
the change measured here. So this replays, in one process, every call of
:meth:`StateFilter.first_colliding <baseplace.world.state_filter.StateFilter.first_colliding>`
that the product's ``MotionChecker.check`` makes on the checks of a ``bench_motion_verdicts``
results file (its inputs, development seeds 0-2 only; the same OMPL seed), and times each
recorded call with no lever arms (every pair tested at every state) and with the arm's lever arms
(conservative advancement, :func:`~baseplace.world.state_filter._mark`), alternated
none/levers/levers/none. The answers (the first touching state of each call) must be identical.
Split by calls whose line is free (-1) and those blocked.

Usage: python bench/bench_edge_replay.py [--results motion_verdicts_s14_main_a] [--checks 72]
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

import profile_motion_stages as stages
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.world import state_filter
from common import RESULTS, report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="motion_verdicts_s14_main_a", help="bench/results/NAME.json")
    parser.add_argument("--checks", type=int, default=72)
    parser.add_argument("--name", default="edge_replay_dev")
    args = parser.parse_args()
    rows = json.loads((RESULTS / f"{args.results}.json").read_text())["checks"][: args.checks]
    assert not set(range(3, 14)) & {row["seed"] for row in rows}, "held-out seeds"
    calls: list[tuple[Any, ...]] = []
    inner = state_filter.StateFilter.first_colliding

    def recording(self: Any, Q: Any, T: Any, levers: Any = None) -> int:
        calls.append((self, np.array(Q), np.array(T), levers))
        return inner(self, Q, T, levers)

    state_filter.StateFilter.first_colliding = recording  # type: ignore[method-assign]
    robot = stages.Robot("tiago")
    arm = robot.arm(stages.resolve_map(robot, None).rmap.info.arm)
    s = stages.TableGridSettings()
    for row in rows:
        target = np.array(row["target"])
        _, _, seen = stages.trial_scene(row["seed"], tuple(row["cell"]), s)
        points = stages.with_floor(seen, 0.0)
        cache = stages.SceneCache(points)
        checks = stages.scene_checks(robot, arm.name, points, cache.terrain(None), target[None],
                                     stages.PlaceSettings(), "auto", cache)  # fmt: skip
        motion = checks.verifier.motion
        assert motion is not None
        checker = MotionChecker(robot, arm, motion.environment, motion.approach_environment, MotionSettings())
        seed = stages.check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        checker.check(np.array(row["q_grasp"]), np.array(row["T_world_base"]), target, seed=seed)
    state_filter.StateFilter.first_colliding = inner  # type: ignore[method-assign]
    levers = next(c[3] for c in calls if c[3] is not None)
    ms: dict[str, list[float]] = {"none": [], "levers": []}
    split: dict[str, float] = {}
    answers: dict[str, list[int]] = {}
    for mode in ("none", "levers", "levers", "none"):
        got, total = [], 0.0
        for filt, Q, T, lv in calls:
            t = time.perf_counter()
            got.append(inner(filt, Q, T, levers if mode == "levers" and lv is not None else None))
            dt = time.perf_counter() - t
            total += dt
            key = f"{mode}_{'free' if got[-1] < 0 else 'blocked'}_ms"
            split[key] = split.get(key, 0.0) + dt * 1e3 / 2
        ms[mode].append(round(total * 1e3, 1))
        assert answers.setdefault(mode, got) == got
    assert answers["none"] == answers["levers"], "certificates ahead changed an answer"
    result = {
        "results_file": args.results,
        "checks": len(rows),
        "seeds": sorted({row["seed"] for row in rows}),
        "calls": len(calls),
        "states": int(sum(len(c[1]) for c in calls)),
        "answers_identical": True,
        "total_ms": ms,
        "ratio_none_over_levers": round(float(np.mean(ms["none"]) / np.mean(ms["levers"])), 2),
        "split_ms_mean_of_two": {k: round(v, 1) for k, v in sorted(split.items())},
    }
    report(args.name, result, split="dev")


if __name__ == "__main__":
    main()
