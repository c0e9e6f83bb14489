"""Why the default method's executed draws fail on the table-grid execution dev seeds (protocol v6, or v10).

Development data only: seeds 0, 1, 2 (any other seed is refused; 14-19 are held-out). Each trial
is run exactly as ``bench/bench_execution.py --protocol 6`` runs it (its protocol table, map,
robot shapes and ``execution_trial``), with recorders wrapped around the calls the execution makes;
they only observe (no generator is drawn from, no verdict changed), so the outcomes equal that
script's (seed 0 is checked against ``execution_table_grid_dev_v6.json`` by the reader). Only the
robust ranking is cheaper here (pool 1, 1 draw): it is not analysed, and it draws nothing the
default method's trials use. For every failed draw of the default method:

* ``no_grasp``: per grasp, how many of the robot's IK starts gave a solution, how many were within
  the limits, how many its own model refused; for the refused ones, each (link, what it touched)
  with the oracle's verdict on that configuration (the true scene, coal) and the TRUE clearance of
  that link to the true table (and, for a link outside the hand, the bottle) by coal distance.
* ``no_motion``: per planned grasp, the phase that failed: ``approach`` (with the walk reasons of
  ``bench/find_rate_dev_extra.py``'s ``ApproachRecorder``) or ``transit`` (an end state colliding,
  or RRTConnect without a path after its checks), the contacts the planner reported and the true
  clearance of the contacting link in the blocking configuration.
* ``no_placement``: the IRM search's verifier checks, by outcome (``bench/irm_pool_dev.py``'s
  recording verifier).

Usage: NUMBA_NUM_THREADS=1 python bench/execution_failures_dev.py [--seeds 0 1 2] [--cells 12] [--protocol 10]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))

import baseplace.placement.irm_candidates as irm_module
import baseplace_experiments.execution as execution_module
from baseplace.errors import InputError
from baseplace.placement.motion import MotionChecker
from baseplace.placement.robustness import RobustnessSettings
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace_experiments.execution import ExecutionOracle
from baseplace_experiments.execution_experiment import EXECUTION_METHODS, execution_trial
from baseplace_experiments.results import SeedSplit
from baseplace_experiments.table_grid import RobotShapes
from bench_execution import DRAWS, PROTOCOLS, ROBUST_KEY, SUPPORT_MODEL
from common import report
from find_rate_dev_extra import ApproachRecorder
from irm_pool_dev import LOG, _recording, failure_class

PROTOCOL = 6
DEV_SEEDS = (0, 1, 2)
HELD_OUT = (14, 15, 16, 17, 18, 19)  # protocols v5 and v6's held-out seeds: never run here
CHEAP_ROBUST = RobustnessSettings(samples=1, ik_solutions=1, pool=1)
"""The robust method is not analysed here; its scoring draws nothing the default method uses."""


class Recorder:
    """Observes ``ExecutionOracle.execute`` and what it calls, one record per execute call."""

    def __init__(self) -> None:
        self.calls: list[dict[str, Any]] = []
        self.approach = ApproachRecorder()
        self.executing = False
        """Inside an execute call (the IRM search's motion checks are not recorded)."""

    def install(self) -> None:
        recorder = self
        self.approach.install()
        execute = ExecutionOracle.execute
        own = execution_module.own_grasp_configuration
        check = MotionChecker.check

        def rec_execute(oracle: ExecutionOracle, T: Any, grasps: Any, planner: Any, rng: Any) -> str:
            call: dict[str, Any] = {"oracle": oracle, "T": np.asarray(T, dtype=float), "grasps": [],
                                    "motions": [], "true_grasps": np.asarray(grasps, dtype=float)}  # fmt: skip
            recorder.calls.append(call)
            recorder.executing = True
            try:
                call["outcome"] = execute(oracle, T, grasps, planner, rng)
            finally:
                recorder.executing = False
            return call["outcome"]

        def rec_own(planner: MotionChecker, T: Any, grasp: Any, rng: Any, starts: int) -> Any:
            environment = planner.approach_environment or planner.environment
            solved: list[Any] = []
            judged: list[tuple[Any, bool]] = []
            colliding_arm, solve_from = environment.colliding_arm, DampedLeastSquaresIK.solve_from

            def rec_colliding(arm: Any, q: Any, T_base: Any) -> bool:
                hit = colliding_arm(arm, q, T_base)
                judged.append((np.array(q, dtype=float), hit))
                return hit

            def rec_solve(ik: Any, T_target: Any, seeds: Any) -> Any:
                q = solve_from(ik, T_target, seeds)
                solved.append(q)
                return q

            environment.colliding_arm = rec_colliding  # type: ignore[method-assign]
            DampedLeastSquaresIK.solve_from = rec_solve  # type: ignore[method-assign]
            try:
                q = own(planner, T, grasp, rng, starts)
            finally:
                del environment.colliding_arm
                DampedLeastSquaresIK.solve_from = solve_from  # type: ignore[method-assign]
            recorder.calls[-1]["grasps"].append({"grasp": np.asarray(grasp, dtype=float), "solved": solved,
                                                 "judged": judged, "found": q is not None,
                                                 "environment": environment, "arm": planner.arm})  # fmt: skip
            return q

        def rec_check(planner: MotionChecker, q: Any, T: Any, T_tcp: Any, seed: int = 0) -> Any:
            before, checks0 = Counter(recorder.approach.outcomes), planner.state_checks
            motion = check(planner, q, T, T_tcp, seed)
            if not recorder.executing:
                return motion
            walk = dict(recorder.approach.outcomes - before)
            row: dict[str, Any] = {"planned": motion is not None, "approach": walk,
                                   "transit_checks": planner.state_checks - checks0}  # fmt: skip
            if motion is None:
                refused = any(k.startswith("refused") for k in walk)
                row["phase"] = "approach" if refused else "transit"
                row["contacts"] = [list(c) for c in planner.last_contacts]
                blocked = planner._blocked
                row["blocked"] = None if blocked is None else (np.array(blocked[0]), blocked[1])
                if blocked is not None and blocked[1] == "transit":  # joint_path checks its two ends
                    row["blocked_state"] = (
                        "start" if np.array_equal(blocked[0], planner.q_start) else "pregrasp"
                    )
                if not refused:
                    limit = planner.settings.max_checks
                    row["transit"] = ("end_state_collides" if blocked is not None and blocked[1] == "transit"
                                      else "rrt_budget" if limit is not None and row["transit_checks"] >= limit
                                      else "rrt_no_path")  # fmt: skip
            recorder.calls[-1]["motions"].append(row)
            return motion

        ExecutionOracle.execute = rec_execute  # type: ignore[method-assign]
        execution_module.own_grasp_configuration = rec_own
        MotionChecker.check = rec_check  # type: ignore[method-assign]


def link_clearance(shapes: RobotShapes, link: str, q: Any, T_world_base: Any, with_bottle: bool,
                   oracle: ExecutionOracle) -> float:  # fmt: skip
    """Least coal distance [m] of the link's collision geometries to the true shapes (negative: inside)."""
    q_full = shapes.arm.to_pinocchio(q, shapes.robot.q_reference)
    pin.framesForwardKinematics(shapes.model, shapes.data, q_full)
    pin.updateGeometryPlacements(shapes.model, shapes.data, shapes.geom, shapes.geom_data, q_full)
    T_world_root = np.asarray(T_world_base, dtype=float) @ shapes.T_base_root
    targets = list(oracle.scene) + ([oracle.grasped] if with_bottle and oracle.grasped is not None else [])
    best = float("inf")
    for k, obj in enumerate(shapes.geom.geometryObjects):
        if str(shapes.model.frames[obj.parentFrame].name) != link:
            continue
        T = T_world_root @ shapes.geom_data.oMg[k].homogeneous
        T_geom = coal.Transform3s(T[:3, :3], T[:3, 3])
        for shape in targets:
            result = coal.DistanceResult()
            d = coal.distance(obj.geometry, T_geom, shape.geometry, shape.transform(),
                              coal.DistanceRequest(), result)  # fmt: skip
            best = min(best, float(d))
    return best


def contact_rows(oracle: ExecutionOracle, environment: Any, arm: Any, q: Any, T: Any, hand_may_touch: bool,
                 contacts: list[tuple[str, str]] | None = None) -> dict[str, Any]:  # fmt: skip
    """The model's contacts at ``q`` with the true verdict and each link's true clearance [mm]."""
    shapes = oracle.shapes
    hand_links = {
        str(shapes.model.frames[shapes.geom.geometryObjects[k].parentFrame].name) for k in shapes.hand
    }
    pairs = contacts if contacts is not None else environment.contacts_arm(arm, q, T)
    true = shapes.touching(q, T, oracle.scene if hand_may_touch else [*oracle.scene, oracle.grasped],
                           oracle.grasped if hand_may_touch else None)  # fmt: skip
    out = []
    for link, what in pairs:
        if what.startswith("self"):
            out.append({"link": link, "touched": what, "true_clearance_mm": None})
            continue
        bottle = not hand_may_touch or link not in hand_links
        d = link_clearance(shapes, link, q, T, bottle, oracle)
        out.append({"link": link, "touched": what, "true_clearance_mm": round(1e3 * d, 1)})
    return {"true_touching": true, "contacts": out}


def analyse(call: dict[str, Any]) -> dict[str, Any]:
    """One failed draw of the default method, JSON-ready."""
    oracle, T = call["oracle"], call["T"]
    row: dict[str, Any] = {"outcome": call["outcome"], "base": [round(float(T[0, 3]), 4), round(float(T[1, 3]), 4),
                           round(float(np.arctan2(T[1, 0], T[0, 0])), 4)]}  # fmt: skip
    p_bottle = oracle.grasped.T_world_shape[:3, 3]
    row["base_to_bottle_m"] = round(float(np.hypot(*(p_bottle[:2] - T[:2, 3]))), 4)
    # the oracle's own generator: the robot's draws stay as the execution made them
    oracle_rng = np.random.default_rng(0)
    row["oracle_grasps_free"] = sum(bool(oracle.grasp_configurations(T, G, oracle_rng, limit=1))
                                    for G in call["true_grasps"])  # fmt: skip
    grasps = []
    contact_counter: Counter[str] = Counter()
    clearances: dict[str, list[float]] = {}
    true_verdicts: Counter[str] = Counter()
    for g in call["grasps"]:
        solved = [q for q in g["solved"] if q is not None]
        refused = [q for q, hit in g["judged"] if hit]
        entry: dict[str, Any] = {"ik_starts": len(g["solved"]), "ik_solutions": len(solved), "within_limits": len(g["judged"]),
                                 "model_refused": len(refused), "found": g["found"]}  # fmt: skip
        details = []
        for q in refused:
            d = contact_rows(oracle, g["environment"], g["arm"], q, T, hand_may_touch=True)
            details.append(d)
            true_verdicts["free on true scene" if d["true_touching"] is None else "touches true scene"] += 1
            for c in d["contacts"]:
                key = f"{c['link']} / {c['touched']}"
                contact_counter[key] += 1
                if c["true_clearance_mm"] is not None:
                    clearances.setdefault(key, []).append(c["true_clearance_mm"])
        entry["refused"] = details[:3]
        grasps.append(entry)
    row["grasps_tried"] = len(grasps)
    row["grasps_with_ik"] = sum(g["ik_solutions"] > 0 for g in grasps)
    row["grasps_within_limits"] = sum(g["within_limits"] > 0 for g in grasps)
    row["grasps_found"] = sum(g["found"] for g in grasps)
    row["refused_configurations_true_verdict"] = dict(true_verdicts)
    row["refusal_contacts"] = dict(contact_counter.most_common())
    row["refusal_true_clearance_mm"] = {k: {"min": min(v), "median": float(np.median(v)), "max": max(v)}
                                        for k, v in clearances.items()}  # fmt: skip
    row["grasps"] = grasps
    motions = []
    for m in call["motions"]:
        out = {k: v for k, v in m.items() if k != "blocked"}
        blocked = m.get("blocked")
        if blocked is not None:
            q, stage = blocked
            planner_env = call["grasps"][0]["environment"]
            out["blocked_true"] = contact_rows(oracle, planner_env, call["grasps"][0]["arm"], q, T,
                                               hand_may_touch=stage == "approach",
                                               contacts=[(link, what.split(" during")[0]) for link, what in m["contacts"]])  # fmt: skip
        motions.append(out)
    row["motions"] = motions
    return row


def cause(row: dict[str, Any]) -> str:
    """One word (and a detail) per failed draw: what the next session would fix."""
    if row["outcome"] == "no_grasp":
        if row["grasps_with_ik"] == 0:
            truth = (
                "out of reach on the true scene too" if row["oracle_grasps_free"] == 0 else "oracle grasps"
            )
            return f"no_grasp: no IK solution ({truth})"
        if row["grasps_within_limits"] == 0:
            return "no_grasp: IK only outside limits"
        verdicts = row["refused_configurations_true_verdict"]
        free = verdicts.get("free on true scene", 0)
        return f"no_grasp: model refused ({'some' if free else 'none'} free on true scene)"
    if row["outcome"] == "no_motion" and row["oracle_grasps_free"] == 0:
        return "no_motion: oracle finds no free grasp either"
    if row["outcome"] == "no_motion":
        phases = Counter(
            f"{m['transit']} ({m['blocked_state']})"
            if "blocked_state" in m
            else m.get("transit", m.get("phase"))
            for m in row["motions"]
        )
        return "no_motion: " + "+".join(f"{k} x{v}" for k, v in sorted(phases.items()))
    return row["outcome"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(DEV_SEEDS))
    parser.add_argument("--cells", type=int, default=12, help="cells per seed (first N of the 3 x 4 grid)")
    parser.add_argument("--protocol", type=int, choices=(6, 10), default=PROTOCOL,
                        help="bench_execution's protocol to run the trials as (default 6)")  # fmt: skip
    args = parser.parse_args(argv)
    if not args.seeds or any(seed not in DEV_SEEDS for seed in args.seeds):
        raise InputError(f"development seeds only ({', '.join(map(str, DEV_SEEDS))}), got {args.seeds}")
    cut, _, motion = PROTOCOLS[args.protocol]
    recorder = Recorder()
    recorder.install()
    irm_module.Verifier = _recording  # type: ignore[misc,assignment]
    robot = Robot("tiago")
    rmap = build_map(robot, None, BuildSettings(samples=10_000_000, seed=1))
    shapes = RobotShapes(robot, rmap.info.arm)
    cells = [(i, j) for j in range(4) for i in range(3)][: args.cells]
    trials: list[dict[str, Any]] = []
    done: list[int] = []
    for seed in args.seeds:
        for cell in cells:
            recorder.calls.clear()
            LOG.clear()
            t = execution_trial(robot, rmap, shapes, seed, cell, CHEAP_ROBUST, ROBUST_KEY, DRAWS, cut=cut,
                                motion=motion, support=SUPPORT_MODEL[args.protocol])  # fmt: skip
            placed = [m for m in EXECUTION_METHODS if t["methods"][m]["pose"] is not None]
            assert len(recorder.calls) == DRAWS * len(placed)
            first = placed.index("default") * DRAWS if "default" in placed else None
            default = t["methods"]["default"]
            p_true = np.asarray(t["true"], dtype=float)
            nominal = (
                None
                if default["pose"] is None
                else round(float(np.hypot(*(p_true[:2] - default["pose"][:2]))), 4)
            )
            row: dict[str, Any] = {"seed": seed, "cell": list(cell), "pool": t["pool"], "pose": default["pose"],
                                   "base_to_bottle_m": nominal,
                                   "outcomes": default["outcomes"],
                                   "irm_checks": dict(Counter(failure_class(r) for r in LOG).most_common())}  # fmt: skip
            failures = []
            if first is not None:
                for call in recorder.calls[first : first + DRAWS]:
                    if call["outcome"] != "ok":
                        failure = analyse(call)
                        failure["cause"] = cause(failure)
                        failures.append(failure)
            row["failures"] = failures
            trials.append(row)
            print(seed, cell, default["outcomes"], [f["cause"] for f in failures], flush=True)
        done.append(seed)
        write(trials, done, len(cells), args.protocol)
    return 0


def write(trials: list[dict[str, Any]], seeds: list[int], cells: int, protocol: int) -> None:
    """The classification so far, per seed and overall, with provenance."""
    per_seed: dict[str, Any] = {}
    for seed in seeds:
        rows = [t for t in trials if t["seed"] == seed]
        outcomes = Counter(o for t in rows for o in t["outcomes"])
        causes = Counter(f["cause"] for t in rows for f in t["failures"])
        causes["no_placement"] += outcomes.get("no_placement", 0)  # each trial's irm_checks say why
        contacts: Counter[str] = Counter()
        for t in rows:
            for f in t["failures"]:
                for m in f["motions"]:
                    for c in m.get("contacts", []):
                        contacts[f"{m.get('phase')}: {c[0]} / {c[1]}"] += 1
                for k, v in f["refusal_contacts"].items():
                    contacts[f"grasp: {k}"] += v
        per_seed[str(seed)] = {"draws": sum(len(t["outcomes"]) for t in rows), "outcomes": dict(outcomes),
                               "causes": dict(causes.most_common()),
                               "contacts": dict(contacts.most_common())}  # fmt: skip
    result = {"protocol": {"version": protocol, "method": "default", "cells": cells, "draws": DRAWS,
                           "robust_not_analysed": {"pool": CHEAP_ROBUST.pool, "samples": CHEAP_ROBUST.samples}},
              "per_seed": per_seed, "trials": trials}  # fmt: skip
    name = "execution_failures_dev" if protocol == PROTOCOL else f"execution_failures_dev_v{protocol}"
    report(name, result, seeds=SeedSplit(dev=DEV_SEEDS, held_out=HELD_OUT), split="dev",
           used_seeds=seeds)  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
