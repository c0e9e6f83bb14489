"""The approach restarts on the table-grid dev checks: which refusals more (or better-seeded) restarts
recover, and what they cost (development data only).

Replays the checks of a ``bench_motion_verdicts.py`` dev results file (its inputs: seed, cell,
grasp, base pose, target, grasp configuration, OMPL seed; every held-out seed refused, as
``profile_motion_stages.py`` does), rebuilding each scene's two collision models as that bench does
(``scene_checks`` on the scene's cache), and runs each check with every ``--variants`` checker
(:data:`VARIANTS`: the product's ``MotionSettings()`` with other ``approach_restarts``, and the
reference). ``--refused-only``: only the checks the file's product refused. Per check and variant:
the verdict, the wall time, and for a motion found which approach restart gave it (0: the walk back
from the verified grasp configuration) and whether it passes the state-by-state re-check in its own
models (``bench_motion_verdicts.recheck``) and the true table and bottle
(``bench_motion_verdicts.true_scene``, the execution oracle).

Usage: python bench/approach_restarts_dev.py --results motion_verdicts_s15_wide_dev
       --out bench/results/approach_restarts_s15_dev.json [--variants product restarts8 reference]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import dataclasses
import json
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.errors import InputError
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.results import RunClock, write_results
from baseplace_experiments.table_grid import RobotShapes, TableGridSettings, true_bottle, true_table
from bench_motion_verdicts import (
    APPROACH_VARIANTS,
    PROTOCOLS,
    RECHECK,
    check_seed,
    recheck,
    row_models,
    true_scene,
)

RESULTS = Path(__file__).parent / "results"
VARIANTS: dict[str, MotionSettings] = {
    **APPROACH_VARIANTS,
    "seeded4": MotionSettings(),
    "seeded8": MotionSettings(approach_restarts=8),
}
SEEDED = {"seeded4": 4, "seeded8": 4}
"""Variants whose first restarts' IK starts from the grasp configuration (the first), then from it
perturbed (:class:`SeededArm`), instead of uniform random configurations."""
PERTURBATION = 0.3
"""Standard deviation [rad or m, per joint] of the perturbed grasp configurations."""


class SeededArm:
    """The arm, whose first ``seeded`` samples (the restarts' IK starts) are the grasp configuration and
    perturbations of it."""

    def __init__(self, arm: Any, q_grasp: np.ndarray, seeded: int) -> None:
        self._arm, self._q, self._left, self._first = arm, q_grasp, seeded, True

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self._left <= 0:
            return self._arm.sample(rng, n)
        self._left -= 1
        if self._first:
            self._first = False
            return self._q[None].copy()
        q = self._q + rng.normal(0.0, PERTURBATION, size=self._q.shape)
        return np.clip(q, self._arm.lower, self._arm.upper)[None]

    def __getattr__(self, name: str) -> Any:
        return getattr(self._arm, name)


def restarts_counted(checker: MotionChecker) -> list[int]:
    """Counts the pre-grasp IK calls of ``checker``'s approach restarts (one per restart)."""
    count = [0]
    solve = checker._ik_any.solve

    class Counting:
        def __getattr__(self, name: str) -> Any:
            return getattr(checker._ik_any_inner, name)

        def solve(self, *args: Any, **kwargs: Any) -> Any:
            count[0] += 1
            return solve(*args, **kwargs)

    checker._ik_any_inner = checker._ik_any  # type: ignore[attr-defined]
    checker._ik_any = Counting()  # type: ignore[assignment]
    return count


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--results", required=True, help="bench/results/NAME.json of bench_motion_verdicts.py (dev)"
    )
    parser.add_argument("--out", required=True)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=["product", "reference"])
    parser.add_argument(
        "--refused-only", action="store_true", help="only the checks the file's product refused"
    )
    args = parser.parse_args(argv)
    clock = RunClock()
    rows = json.loads((RESULTS / f"{args.results}.json").read_text())["checks"]
    held_out = {*range(3, 38), *(seed for _, seeds in PROTOCOLS.values() for seed in seeds)}
    if held_out & {row["seed"] for row in rows}:
        raise InputError(f"{args.results} holds held-out seeds")
    if args.refused_only:
        rows = [row for row in rows if not row["product"]["found"]]
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    arm = robot.arm(rmap.info.arm)
    s = TableGridSettings()
    shapes = RobotShapes(robot, arm.name)
    true_step = ExecutionSettings(path_step=MotionSettings().joint_resolution / RECHECK)
    models: dict[tuple[Any, ...], Any] = {}
    out_rows = []
    for row in rows:
        key = (row["seed"], tuple(row["cell"]), row["grasp"])
        target = np.array(row["target"])
        if key not in models:
            transit, approach_env, p_true = row_models(robot, arm.name, row)
            oracle = ExecutionOracle(shapes, true_table(s), true_bottle(p_true, s), true_step)
            models[key] = (transit, approach_env, oracle)
        transit, approach_env, oracle = models[key]
        seed = check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        q, T_base = np.array(row["q_grasp"]), np.array(row["T_world_base"])
        out: dict[str, Any] = {k: row[k] for k in ("seed", "cell", "grasp", "placement")}
        out["file_product"] = {"found": row["product"]["found"], "reason": row["product"].get("reason")}
        for name in args.variants:
            checker = MotionChecker(robot, arm, transit, approach_env, VARIANTS[name])
            if name in SEEDED:
                checker.arm = SeededArm(arm, q, SEEDED[name])  # type: ignore[assignment]
            count = restarts_counted(checker)
            t = time.perf_counter()
            motion = checker.check(q, T_base, target, seed=seed)
            x: dict[str, Any] = {"found": motion is not None, "wall_ms": round((time.perf_counter() - t) * 1e3, 2),
                                 "restarts_tried": count[0]}  # fmt: skip
            if motion is not None:
                x["approach_from_restart"] = count[0]
                x["recheck_colliding"] = recheck(checker, motion.path, motion.approach, T_base)["colliding"]
                x["true_scene"] = true_scene(oracle, motion.path, motion.approach, T_base)
            out[name] = x
        out_rows.append(out)
        print(key, row["placement"], {n: (out[n]["found"], out[n]["wall_ms"], out[n].get("approach_from_restart"))
                                      for n in args.variants}, flush=True)  # fmt: skip
    summary: dict[str, Any] = {"checks": len(out_rows)}
    for name in args.variants:
        r = [o[name] for o in out_rows]
        walls = [x["wall_ms"] for x in r]
        summary[name] = {
            "found": sum(x["found"] for x in r),
            "found_by_restart": sum(1 for x in r if x["found"] and x["approach_from_restart"] > 0),
            "approach_from_restart": dict(Counter(x["approach_from_restart"] for x in r if x["found"])),
            "found_touching_at_finer_recheck": sum(1 for x in r if x["found"] and x["recheck_colliding"]),
            "found_touching_true_scene": sum(1 for x in r if x["found"] and any(x["true_scene"].values())),
            "ms_median": round(float(np.median(walls)), 2) if walls else None,
            "ms_p90": round(float(np.quantile(walls, 0.9)), 2) if walls else None,
        }
    result = {"benchmark": "approach_restarts_dev", "results": args.results, "refused_only": args.refused_only,
              "variants": {n: dataclasses.asdict(VARIANTS[n]) for n in args.variants},
              "summary": summary, "checks": out_rows}  # fmt: skip
    write_results(args.out, result, clock, used_seeds=sorted({o["seed"] for o in out_rows}))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
