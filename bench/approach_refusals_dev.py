"""Which motion refusals of ``place`` on the find-rate dev scenes a 100x-budget checker solves, and where
the product's check failed (development data only).

For every find-rate dev scene (seeds 25000-25059; the held-out seeds are refused) that a source
results file marks as solvable by its oracle and refused by ``place`` with motion failures, ``place``
runs again as ``bench/find_rate.py`` runs it (``run_place``: its defaults, the noisy cloud, the
grasp point). Each reaching-motion check the verification makes (``Verifier`` calling
``MotionChecker.check``: the candidates that passed the pose checks) is recorded with its inputs
(grasp configuration, base pose, target, OMPL seed) and the checker's two collision models, the
very ones ``place`` built. Up to ``--per-scene`` refused checks per scene are then checked again by

* ``reference``: ``bench_motion_verdicts.REFERENCE`` (100 s, 50 000 transit checks, 40 approach
  restarts) on the same models and seed;
* each ``--variants`` checker: the product's ``MotionSettings()`` with other approach settings.

Per check, the stage where it failed: ``approach`` (the walk back from the verified grasp
configuration failed, ``back``: ``grasp_collides``, ``walk``, or ``not_clear``, and every restart
failed: pre-grasp IK none, pre-grasp colliding, forward walk failed), ``transit_ends`` (the start or
pre-grasp configuration collides in the transit model), ``rrt`` (no RRTConnect path in the budget);
for a motion found, whether its approach came from the walk back or which restart. Every motion a
re-run finds is re-checked state by state (joint lines at ``joint_resolution / 4``) in its own
models, and its approach states and transit waypoints (cut at the same step) on the true scene by
find_rate's oracle (coal on the URDF's meshes; the hand may touch the grasped bottle).

Usage: python bench/approach_refusals_dev.py --from bench/results/find_rate_s14_dev_extra_after.json
       --out bench/results/approach_refusals_s15_dev.json [--per-scene 10] [--variants restarts8]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import dataclasses
import itertools
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.errors import InputError
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.robots.model import Robot
from baseplace_experiments.results import RunClock, write_results
from bench_motion_verdicts import APPROACH_VARIANTS, recheck
from find_rate import SEEDS, Oracle, Scene, make_scene, run_place, scenes_by_seed

VARIANTS: dict[str, MotionSettings] = APPROACH_VARIANTS
"""The checkers a refused check is run again with (``product``: the same settings, to see the verdict repeat)."""


class _Solving:
    """An IK solver whose ``solve`` is another function (the solver's dataclass is frozen)."""

    def __init__(self, ik: Any, solve: Any, name: str = "solve") -> None:
        self._ik = ik
        setattr(self, name, solve)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ik, name)


class Trace:
    """What one ``MotionChecker.check`` did, stage by stage (installed on a checker instance)."""

    def __init__(self, checker: MotionChecker) -> None:
        self.reset()
        approach, walk, rrt = checker.approach, checker._walk, checker._rrt
        solve, solve_from = checker._ik_any.solve, checker._ik.solve_from
        approach_free = checker._approach_free

        def traced_approach(*args: Any, **kwargs: Any) -> Any:
            self.approach_called = True
            out = approach(*args, **kwargs)
            self.approach_found = out is not None
            return out

        def traced_walk(*args: Any, **kwargs: Any) -> Any:
            self._solved, blocked = [], checker._blocked
            out = walk(*args, **kwargs)
            self.walks.append(out is not None)
            if out is None:  # why: the last IK failed, a joint line collided, else a jump
                why = "ik" if self._solved and self._solved[-1] is None else "jump"
                if checker._blocked is not blocked:
                    why = "collision"
                self.walk_failures.append(f"{why} after {sum(q is not None for q in self._solved)} solves")
            return out

        def traced_solve_from(*args: Any, **kwargs: Any) -> Any:
            q = solve_from(*args, **kwargs)
            self._solved.append(q)
            return q

        def traced_solve(*args: Any, **kwargs: Any) -> Any:
            q = solve(*args, **kwargs)
            self.restarts.append("ik" if q is None else "?")
            return q

        def traced_free(q: Any, T: Any) -> bool:
            free = approach_free(q, T)
            self.free_checks.append(free)
            if self.restarts and self.restarts[-1] == "?" and not free:
                self.restarts[-1] = "pregrasp_collides"
            return free

        def traced_rrt(*args: Any, **kwargs: Any) -> Any:
            self.rrt_called = True
            return rrt(*args, **kwargs)

        checker.approach = traced_approach  # type: ignore[method-assign]
        checker._walk = traced_walk  # type: ignore[method-assign]
        checker._ik_any = _Solving(checker._ik_any, traced_solve)  # type: ignore[assignment]
        checker._ik = _Solving(checker._ik, traced_solve_from, "solve_from")  # type: ignore[assignment]
        checker._approach_free = traced_free  # type: ignore[method-assign]
        checker._rrt = traced_rrt  # type: ignore[method-assign]

    def reset(self) -> None:
        self.approach_called = self.approach_found = self.rrt_called = False
        self.walks: list[bool] = []
        self.restarts: list[str] = []
        self.free_checks: list[bool] = []
        self.walk_failures: list[str] = []
        self._solved: list[Any] = []

    def stage(self, checker: MotionChecker, found: bool) -> dict[str, Any]:
        """The failing stage (or how the approach was found) of the last check."""
        n = len(self.restarts)
        back_walked = bool(self.free_checks) and self.free_checks[0]
        back_ok = back_walked and n == 0 and self.approach_found
        out: dict[str, Any] = {"restarts_tried": n, "walk_failures": dict(Counter(self.walk_failures))}
        if self.approach_found:
            out["approach_from"] = "walk_back" if back_ok else f"restart {n}"
        if not back_ok:
            if not back_walked:
                out["back"] = "grasp_collides"
            else:
                out["back"] = "walk" if not self.walks[0] else "not_clear"
            walked = iter(self.walks[1:] if back_walked else self.walks)
            tried = []
            for r in self.restarts:
                if r == "?":
                    r = "forward_ok" if next(walked) else "forward_walk"
                tried.append(r)
            out["restarts"] = dict(Counter(tried))
        if found:
            out["stage"] = "found"
        elif not self.approach_found:
            out["stage"] = "approach"
        elif checker._blocked is not None and checker._blocked[1] == "transit":
            out["stage"] = "transit_ends"
        else:
            out["stage"] = "rrt" if self.rrt_called else "other"
        return out


def true_scene(oracle: Oracle, scene: Scene, motion: Any, T_base: np.ndarray, step: float) -> dict[str, int]:
    """Per part, the states of a motion (joint lines cut at ``step``) touching the true scene."""
    out = {}
    for part, waypoints in (("transit", motion.path), ("approach", motion.approach)):
        states = [waypoints[0]]
        for a, b in itertools.pairwise(waypoints):
            k = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
            states += [a + (b - a) * (i / k) for i in range(1, k + 1)]
        out[part] = sum(1 for q in states if oracle.counting(oracle.contacts(q, T_base, scene)))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--from", dest="sources", nargs="+", required=True, help="find-rate dev results files"
    )
    parser.add_argument("--out", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=None, help="only these dev seeds")
    parser.add_argument("--per-scene", type=int, default=10, help="refused checks re-run per scene")
    parser.add_argument("--variants", nargs="*", choices=list(VARIANTS), default=["reference"])
    args = parser.parse_args(argv)
    clock = RunClock()
    verdicts = scenes_by_seed(args.sources)
    seeds = sorted(
        seed
        for seed, r in verdicts.items()
        if r["oracle"]["found"] and not r["method"]["found"] and r["method"]["failures"].get("motion")
    )
    if args.seeds is not None:
        seeds = [seed for seed in seeds if seed in args.seeds]
    if any(seed >= min(SEEDS.held_out) for seed in [*verdicts, *(args.seeds or [])]):
        raise InputError("development seeds only: held-out scenes given")
    recorded: list[dict[str, Any]] = []
    original = MotionChecker.check

    def recording(self: MotionChecker, q: Any, T_base: Any, T_tcp: Any, seed: int = 0) -> Any:
        if not hasattr(self, "_trace"):
            self._trace = Trace(self)  # type: ignore[attr-defined]
        trace: Trace = self._trace  # type: ignore[attr-defined]
        trace.reset()
        t = time.perf_counter()
        motion = original(self, q, T_base, T_tcp, seed)
        wall = time.perf_counter() - t
        caller = sys._getframe(1).f_code.co_filename
        if caller.endswith("verify.py"):
            recorded.append({"checker": self, "q": np.array(q), "T_base": np.array(T_base),
                             "T_tcp": np.array(T_tcp), "seed": seed, "found": motion is not None,
                             "wall_ms": round(wall * 1e3, 2), **trace.stage(self, motion is not None)})  # fmt: skip
        return motion

    MotionChecker.check = recording  # type: ignore[method-assign]
    robot = Robot("tiago")
    oracle = Oracle(robot)
    arm = oracle.arm
    step = MotionSettings().joint_resolution / 4
    rows: list[dict[str, Any]] = []
    for seed in seeds:
        scene = make_scene(seed)
        if verdicts[seed]["scene"] != scene.record():
            raise InputError(f"scene {seed} differs from its source file's")
        recorded.clear()
        method = run_place(scene, oracle)
        refused = [r for r in recorded if not r["found"]]
        stages = Counter(r["stage"] for r in refused)
        print(seed, scene.kind, "place found", method["found"], "motion checks", len(recorded), "refused",
              len(refused), dict(stages), flush=True)  # fmt: skip
        checks = []
        for r in refused[: args.per_scene]:
            product = r["checker"]
            row: dict[str, Any] = {
                "T_world_base": np.round(r["T_base"], 6).tolist(), "target": np.round(r["T_tcp"], 6).tolist(),
                "q_grasp": np.round(r["q"], 6).tolist(), "ompl_seed": r["seed"],
                "product_in_place": {k: v for k, v in r.items() if k not in ("checker", "q", "T_base", "T_tcp", "seed")},
            }  # fmt: skip
            for name in args.variants:
                checker = MotionChecker(robot, arm, product.environment, product.approach_environment,
                                        VARIANTS[name])  # fmt: skip
                trace = Trace(checker)
                t = time.perf_counter()
                motion = original(checker, r["q"], r["T_base"], r["T_tcp"], r["seed"])
                out: dict[str, Any] = {"found": motion is not None,
                                       "wall_ms": round((time.perf_counter() - t) * 1e3, 2),
                                       **trace.stage(checker, motion is not None)}  # fmt: skip
                if motion is not None:
                    out["recheck_colliding"] = recheck(checker, motion.path, motion.approach, r["T_base"])[
                        "colliding"
                    ]
                    out["true_scene"] = true_scene(oracle, scene, motion, r["T_base"], step)
                    out["approach"] = np.round(motion.approach, 6).tolist()
                row[name] = out
            checks.append(row)
            print("  ", r["stage"], r.get("back"), r.get("restarts"),
                  {n: (row[n]["found"], row[n]["stage"], row[n].get("approach_from"), row[n]["wall_ms"])
                   for n in args.variants}, flush=True)  # fmt: skip
        rows.append({"seed": seed, "kind": scene.kind, "place_found": method["found"],
                     "place_failures": method["failures"], "motion_checks": len(recorded),
                     "refused": len(refused), "refused_stages": dict(stages),
                     "refused_back": dict(Counter(r.get("back") for r in refused if r["stage"] == "approach")),
                     "checks": checks})  # fmt: skip
    summary: dict[str, Any] = {
        "scenes": len(rows),
        "motion_checks_in_place": sum(r["motion_checks"] for r in rows),
        "refused_in_place": sum(r["refused"] for r in rows),
        "refused_stages": dict(sum((Counter(r["refused_stages"]) for r in rows), Counter())),
        "rerun": sum(len(r["checks"]) for r in rows),
    }
    for name in args.variants:
        found = [c[name] for r in rows for c in r["checks"]]
        summary[name] = {
            "found": sum(x["found"] for x in found),
            "found_rechecked_free": sum(1 for x in found if x["found"] and x["recheck_colliding"] == 0),
            "found_touching_true_scene": sum(
                1 for x in found if x["found"] and any(x["true_scene"].values())
            ),
            "approach_from": dict(Counter(x.get("approach_from") for x in found if x["found"])),
            "refused_stages": dict(Counter(x["stage"] for x in found if not x["found"])),
            "scenes_with_a_motion": sum(1 for r in rows if any(c[name]["found"] for c in r["checks"])),
            "wall_ms_median": float(np.median([x["wall_ms"] for x in found])) if found else None,
        }
    result = {"benchmark": "approach_refusals_dev", "sources": [Path(p).name for p in args.sources],
              "per_scene": args.per_scene, "variants": {n: dataclasses.asdict(VARIANTS[n]) for n in args.variants},
              "summary": summary, "scenes": rows}  # fmt: skip
    write_results(args.out, result, clock, used_seeds=seeds)
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
