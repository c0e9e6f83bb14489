"""Find rate on extra development scenes, with why each straight approach walk failed.

Development data only: scenes of ``find_rate.make_scene`` for seeds 25010-25059 by default (the
protocol's dev split is 25000-25009; the held-out seeds 25100-25159 are refused here), the same
oracle and the same ``place`` call as ``bench/find_rate.py``. In addition every call of
``MotionChecker.approach`` is classified by how it ended:

* ``found``: an approach walk succeeded;
* else the reasons of its walks (the walk back from the verified grasp configuration, then each
  restart from a pre-grasp IK solution): ``grasp_collides`` (the grasp configuration itself collides
  in the approach model), ``ik`` (no IK solution at a step; ``ik_at_limit`` when the last
  configuration had a joint within 0.01 of a limit), ``jump`` (a step's solution is more than
  ``max_joint_step`` from the last), ``collision`` (a step's joint line collides),
  ``pregrasp_ik`` / ``pregrasp_collides`` (a restart's pre-grasp IK failed or collides).

Usage: python bench/find_rate_dev_extra.py --out x.json [--seeds 25010 25011 ...] [--oracle-from y.json]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.errors import InputError
from baseplace.placement.motion import MotionChecker
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from find_rate import SEEDS, Oracle, make_scene, refusal_reason, run_place, scenes_by_seed, summarise

EXTRA_DEV = tuple(range(25010, 25060))
"""Development seeds beyond the protocol's dev split; never the held-out ones."""
AT_LIMIT = 0.01
"""A joint this close to a limit [rad or m] counts as at the limit."""


class ApproachRecorder:
    """Wraps ``MotionChecker.approach`` and its helpers to classify each approach's failures."""

    def __init__(self) -> None:
        self.outcomes: Counter[str] = Counter()
        self.walk_failures: Counter[str] = Counter()
        self.walk_failure_steps: list[int] = []
        self._events: list[tuple[str, Any]] = []
        self._walks: list[str] = []
        self._in_walk = False
        self._outside = 0

    def install(self) -> None:
        recorder = self
        approach, walk, blocking = MotionChecker.approach, MotionChecker._walk, MotionChecker._blocking
        solve_from, solve = DampedLeastSquaresIK.solve_from, DampedLeastSquaresIK.solve
        approach_free = MotionChecker._approach_free

        def rec_solve_from(ik: DampedLeastSquaresIK, T: Any, seeds: Any) -> Any:
            q = solve_from(ik, T, seeds)
            recorder._events.append(("ik", q))
            return q

        def rec_solve(ik: DampedLeastSquaresIK, *args: Any, **kwargs: Any) -> Any:
            q = solve(ik, *args, **kwargs)  # only the restarts' pre-grasp IK calls it in an approach
            if q is None:
                recorder._walks.append("pregrasp_ik")
            return q

        def rec_blocking(checker: MotionChecker, *args: Any, **kwargs: Any) -> Any:
            q = blocking(checker, *args, **kwargs)
            recorder._events.append(("blocking", q))
            return q

        def rec_free(checker: MotionChecker, q: Any, T: Any) -> bool:
            free = approach_free(checker, q, T)
            if recorder._in_walk:
                return free
            recorder._outside += 1
            if recorder._outside == 1 and not free:
                recorder._walks.append("grasp_collides")
            elif not free:  # the first is the grasp configuration's
                recorder._walks.append("pregrasp_collides")
            return free

        def rec_walk(checker: MotionChecker, q0: Any, poses: Any, T: Any, **kwargs: Any) -> Any:
            recorder._events.clear()
            recorder._in_walk = True
            try:
                steps = walk(checker, q0, poses, T, **kwargs)
            finally:
                recorder._in_walk = False
            if steps is None:
                recorder._walks.append(recorder._classify(checker, q0))
            return steps

        def rec_approach(checker: MotionChecker, q_grasp: Any, *args: Any, **kwargs: Any) -> Any:
            recorder._walks, recorder._outside = [], 0
            recorder._events.clear()
            out = approach(checker, q_grasp, *args, **kwargs)
            walks = recorder._walks
            if out is not None:
                recorder.outcomes["found" if not walks else "found_after_" + "+".join(walks)] += 1
            else:
                first = walks[0] if walks else "?"
                recorder.outcomes["refused: back " + first + ", restarts " + "+".join(walks[1:])] += 1
            for w in walks:
                recorder.walk_failures[w] += 1
            return out

        MotionChecker.approach = rec_approach  # type: ignore[method-assign]
        MotionChecker._walk = rec_walk  # type: ignore[method-assign]
        MotionChecker._blocking = rec_blocking  # type: ignore[method-assign]
        MotionChecker._approach_free = rec_free  # type: ignore[method-assign]
        DampedLeastSquaresIK.solve_from = rec_solve_from  # type: ignore[method-assign]
        DampedLeastSquaresIK.solve = rec_solve  # type: ignore[method-assign]

    def _classify(self, checker: MotionChecker, q0: Any) -> str:
        arm, s = checker.arm, checker.settings
        q_last, step = np.asarray(q0, dtype=float), 0
        for kind, value in self._events:
            if kind == "ik":
                if value is None:
                    self.walk_failure_steps.append(step)
                    near = np.minimum(q_last - arm.lower, arm.upper - q_last) < AT_LIMIT
                    return "ik_at_limit" if np.any(near) else "ik"
                if np.max(np.abs(value - q_last)) > s.max_joint_step:
                    self.walk_failure_steps.append(step)
                    return "jump"
                candidate = value
            elif kind == "blocking":
                if value is not None:
                    self.walk_failure_steps.append(step)
                    return "collision"
                q_last, step = candidate, step + 1
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(EXTRA_DEV))
    parser.add_argument("--out", required=True, help="results JSON")
    parser.add_argument("--oracle-from", default=None, help="reuse the oracle's verdicts of an earlier run")
    args = parser.parse_args(argv)
    held_out = sorted(set(args.seeds) & set(SEEDS.held_out))
    if held_out or any(seed >= min(SEEDS.held_out) for seed in args.seeds):
        raise InputError(f"development seeds only (below {min(SEEDS.held_out)}), got {args.seeds}")
    earlier = scenes_by_seed([args.oracle_from] if args.oracle_from else [])
    recorder = ApproachRecorder()
    recorder.install()
    robot = Robot("tiago")
    oracle = Oracle(robot)
    rows = []
    for seed in args.seeds:
        scene = make_scene(seed)
        record = scene.record()
        if seed in earlier and earlier[seed]["scene"] == record:
            verdict = earlier[seed]["oracle"]
        else:
            verdict = oracle.search(scene, np.random.default_rng([25, seed, 1]))
        before = Counter(recorder.outcomes)
        method = run_place(scene, oracle)
        method["approach"] = dict(recorder.outcomes - before)
        rows.append({"scene": record, "oracle": verdict, "method": method})
        print(seed, scene.kind, "oracle", verdict["found"], "place", method["found"], method["seconds"],
              refusal_reason(method), method["approach"], flush=True)  # fmt: skip
    steps = np.array(recorder.walk_failure_steps)
    result = {
        "benchmark": "find_rate_dev_extra",
        "seeds": args.seeds,
        "summary": summarise(rows),
        "approach_outcomes": dict(recorder.outcomes.most_common()),
        "walk_failures": dict(recorder.walk_failures.most_common()),
        "walk_failure_step_histogram": {
            int(k): int(v) for k, v in zip(*np.unique(steps, return_counts=True), strict=True)
        },
        "scenes": rows,
    }
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(
        json.dumps(
            {k: result[k] for k in ("approach_outcomes", "walk_failures", "walk_failure_step_histogram")}
        )
    )
    print(json.dumps(result["summary"]["all"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
