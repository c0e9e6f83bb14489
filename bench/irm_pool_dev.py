"""Why the IRM candidate search finds no placement where seed 004's radial placement exists (dev only).

Development data only: seeds 0-2 of the table-grid execution experiment (v5's scenes and robot
models, ``execution_experiment.trial_scene`` and ``robot_models(..., "product")``; never a held-out
seed: 14-16 are spent, 17-19 reserved). Per trial it runs the default method's query alone
(``irm_candidates`` with ``IrmSettings()`` and v5's reaching-motion check, the rng of
``execution_trial``), recording every verifier check (pose, grasp, verdict, first contact), and
verifies seed 004's radial candidates with the same verifier (``verify_candidates``). For each
radial pose that verifies, it says why the IRM search did not reach it: the nearest pose of the
IRM grid, whether that position is in the grid (ring, footprint risk), its best map score, its rank
in the search order, and whether the grid pose itself verifies.

Run once per code version with ``--label`` (``before`` on main's code, ``after`` on the fix); each
run adds its block to ``bench/results/irm_pool_dev.json`` and keeps the other labels.

Usage: python bench/irm_pool_dev.py --label after [--seeds 0 1 2] [--cells 12]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

import baseplace.placement.irm_candidates as irm_module
from baseplace.geometry.poses import BasePose
from baseplace.placement.candidates import occupancy_risk, radial_search
from baseplace.placement.irm_candidates import IrmSettings, hand_feasible, irm_candidates, verify_candidates
from baseplace.placement.motion import MotionSettings
from baseplace.placement.verified import Candidate
from baseplace.placement.verify import Verifier
from baseplace.reachability.build import BuildSettings
from baseplace.reachability.cache import cached_map
from baseplace.robots.model import Robot
from baseplace_experiments.execution_experiment import robot_models, trial_scene
from baseplace_experiments.results import SeedSplit
from baseplace_experiments.table_grid import TableGridSettings, radial_settings, table_occupancy
from common import RESULTS, report

DEV_SEEDS = (0, 1, 2)
HELD_OUT = (14, 15, 16, 17, 18, 19)  # spent (14-16) or reserved for the lead's next protocol
MOTION = MotionSettings(time_limit=30.0, max_checks=500, point_step=None)  # v5's planner
NAME = "irm_pool_dev"


class RecordingVerifier(Verifier):
    """The shared verifier, recording each check's pose, grasp and verdict in :data:`LOG`."""

    def check(self, candidate: Candidate, rng: np.random.Generator) -> Any:
        before = len(self.rejected)
        t0 = time.perf_counter()
        placement = super().check(candidate, rng)
        T = candidate.T_world_base
        row: dict[str, Any] = {"x": round(float(T[0, 3]), 3), "y": round(float(T[1, 3]), 3),
                               "yaw": round(math.atan2(T[1, 0], T[0, 0]), 3),
                               "grasp": GRASP_OF[id(self)], "ms": round((time.perf_counter() - t0) * 1e3, 1)}  # fmt: skip
        if placement is not None:
            row["verdict"] = "ok"
        else:
            _, reason, contact = self.rejected[before]
            row["verdict"] = reason
            row["contact"] = None if contact is None else list(contact)
        LOG.append(row)
        return placement


LOG: list[dict[str, Any]] = []
GRASP_OF: dict[int, int] = {}


def _recording(*args: Any, **kwargs: Any) -> RecordingVerifier:
    v = RecordingVerifier(*args, **kwargs)
    GRASP_OF[id(v)] = len(GRASP_OF)
    return v


def failure_class(row: dict[str, Any]) -> str:
    """ "ok", "no_ik", "motion", or "collision: <link> / <what>"."""
    if row["verdict"] == "collision" and row.get("contact"):
        return f"collision: {row['contact'][0]} / {row['contact'][1]}"
    return str(row["verdict"])


def trial(robot: Robot, rmap: Any, seed: int, cell: tuple[int, int], s: TableGridSettings) -> dict[str, Any]:
    """One dev trial: the IRM query recorded, and why the radial placements are not reached."""
    _, p_est, seen = trial_scene(seed, cell, s)
    occupancy = table_occupancy(s)
    env, planner, _ = robot_models(robot, rmap.info.arm, seen, p_est, s, "support", "product", MOTION)
    grasps = s.grasps(p_est, s.method_top_below)
    settings = IrmSettings()
    LOG.clear()
    GRASP_OF.clear()
    irm_module.Verifier = _recording  # type: ignore[misc,assignment]
    try:
        t0 = time.perf_counter()
        pool = irm_candidates(robot, rmap, p_est, grasps, env, occupancy, settings,
                              np.random.default_rng([seed, *cell, 1]), planner)  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        irm_module.Verifier = Verifier  # type: ignore[misc]
    checks = list(LOG)
    positions = {(r["x"], r["y"]) for r in checks}
    per_position: dict[str, Counter[str]] = {}
    for r in checks:
        per_position.setdefault(f"{r['x']:.3f},{r['y']:.3f}", Counter())[failure_class(r)] += 1
    radial = radial_search(p_est, radial_settings(robot, rmap, s), seen, occupancy).candidates
    verified, rejected = verify_candidates(robot, rmap.info.arm, radial, grasps, env,
                                           np.random.default_rng([seed, *cell, 2]), planner)  # fmt: skip
    reached = [why_not_reached(robot, rmap, p_est, grasps, env, occupancy, settings, planner, c.pose, checks, seed, cell)
               for c in verified]  # fmt: skip
    return {
        "seed": seed,
        "cell": list(cell),
        "found": len(pool),
        "found_poses": [
            [round(c.pose.x, 3), round(c.pose.y, 3), round(c.pose.yaw, 3), c.grasp] for c in pool
        ],
        "wall_s": round(wall, 3),
        "checks": len(checks),
        "distinct_positions_checked": len(positions),
        "check_outcomes": dict(Counter(failure_class(r) for r in checks).most_common()),
        "check_s_by_verdict": {
            v: round(sum(r["ms"] for r in checks if r["verdict"] == v) / 1e3, 3)
            for v in sorted({r["verdict"] for r in checks})
        },
        "slowest_check_s": round(max((r["ms"] for r in checks), default=0.0) / 1e3, 3),
        "ok_at_check": [n + 1 for n, r in enumerate(checks) if r["verdict"] == "ok"],
        "per_position": {k: dict(v) for k, v in per_position.items()},
        "radial": {
            "candidates": len(radial),
            "verified": len(verified),
            "rejected": dict(Counter(reason for _, reason in rejected)),
            "verified_not_reached_by_irm": reached,
        },
    }


def why_not_reached(robot: Robot, rmap: Any, p_est: np.ndarray, grasps: np.ndarray, env: Any, occupancy: Any,
                    s: IrmSettings, planner: Any, pose: BasePose, checks: list[dict[str, Any]],
                    seed: int, cell: tuple[int, int]) -> dict[str, Any]:  # fmt: skip
    """Where a verified radial pose falls in the IRM search: the nearest grid pose and its fate."""
    off = np.array([pose.x, pose.y]) - p_est[:2]
    grid_off = np.round(off / s.resolution) * s.resolution
    xy = p_est[:2] + grid_off
    dist = float(np.hypot(*grid_off))
    step = 2 * math.pi / s.n_yaw
    yaw = (round(pose.yaw / step) * step + math.pi) % (2 * math.pi) - math.pi
    T = BasePose(float(xy[0]), float(xy[1]), yaw).matrix()
    values = np.array([rmap.inverse(g, T[None])[0] for g in grasps])
    feasible = hand_feasible(robot, rmap.info.arm, grasps, env)
    best = float((values * feasible).max())
    in_ring = robot.spec.footprint_bounding_radius < dist <= rmap.horizontal_reach
    risk = bool(
        occupancy_risk(occupancy, xy[None], robot.spec.footprint_bounding_radius, s.unknown_is_risk)[0]
    )
    checked = [r for r in checks if math.dist((r["x"], r["y"]), xy) < 1e-3]
    verdict = None
    if (
        in_ring and not risk and best > 0
    ):  # would the grid pose itself verify? (its best grasps, as the search does)
        from baseplace.robots.ik import DampedLeastSquaresIK
        from baseplace.terrain.polygons import footprint_outline

        arm = robot.arm(rmap.info.arm)
        ik = DampedLeastSquaresIK(arm)
        outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
        rng = np.random.default_rng([seed, *cell, 3])
        verdict = "fails"
        for k in np.argsort(-(values * feasible)):
            if values[k] * feasible[k] <= 0:
                break
            if Verifier(arm, ik, env, grasps[k][None], {}, outline, motion=planner).check(
                    Candidate(T, -1, float(values[k])), rng) is not None:  # fmt: skip
                verdict = f"ok (grasp {int(k)})"
                break
    return {
        "radial_pose": [round(pose.x, 3), round(pose.y, 3), round(pose.yaw, 3)],
        "grid_pose": [round(float(xy[0]), 3), round(float(xy[1]), 3), round(yaw, 3)],
        "in_ring": in_ring,
        "footprint_risk": risk,
        "best_score": round(best, 4),
        "hand_feasible_grasps": int(feasible.sum()),
        "checks_at_grid_position": len(checked),
        "grid_pose_verifies": verdict,
    }


def classify(block: dict[str, Any]) -> list[dict[str, Any]]:
    """Per trial with an empty pool: how its checks failed, and why each verified radial pose was not reached."""
    out = []
    for t in block["trials"]:
        if t["found"]:
            continue
        why: Counter[str] = Counter()
        for r in t["radial"]["verified_not_reached_by_irm"]:
            if not r["in_ring"]:
                why["not in the grid's ring"] += 1
            elif r["footprint_risk"]:
                why["footprint occupancy_risk"] += 1
            elif r["best_score"] <= 0:
                why["scored 0 (rmap.inverse x hand_feasible)"] += 1
            elif r["checks_at_grid_position"] == 0:
                ok = str(r["grid_pose_verifies"]).startswith("ok")
                why[
                    "budget: never checked, grid pose verifies"
                    if ok
                    else "budget: never checked, grid pose fails"
                ] += 1
            else:
                why["checked there, failed"] += 1
        out.append({"seed": t["seed"], "cell": t["cell"], "checks": t["checks"],
                    "distinct_positions_checked": t["distinct_positions_checked"],
                    "check_outcomes": t["check_outcomes"], "radial_verified": t["radial"]["verified"],
                    "radial_not_reached_because": dict(why)})  # fmt: skip
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--label", required=True, help="the code version: before (main) or after (the fix)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(DEV_SEEDS))
    parser.add_argument("--cells", type=int, default=12, help="cells per seed (first N of the 3 x 4 grid)")
    args = parser.parse_args()
    if any(seed not in DEV_SEEDS for seed in args.seeds):
        parser.error(f"development seeds only: {', '.join(map(str, DEV_SEEDS))}")
    load_start = os.getloadavg()
    robot = Robot("tiago")
    rmap, _, _ = cached_map(robot, BuildSettings(samples=10_000_000, seed=1))
    s = TableGridSettings()
    cells = [(i, j) for j in range(4) for i in range(3)][: args.cells]
    rows = []
    for seed in args.seeds:
        for cell in cells:
            row = trial(robot, rmap, seed, cell, s)
            print(seed, cell, row["found"], row["wall_s"], row["check_outcomes"],
                  [r["grid_pose_verifies"] for r in row["radial"]["verified_not_reached_by_irm"]], flush=True)  # fmt: skip
            rows.append(row)
    walls = [r["wall_s"] for r in rows]
    block = {
        "code": subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=Path(irm_module.__file__).parent
        ).stdout.strip(),
        "settings": {"irm": IrmSettings().__dict__, "motion_max_checks": MOTION.max_checks},
        "summary": {
            "trials": len(rows),
            "found_per_trial": [r["found"] for r in rows],
            "empty_pools": sum(r["found"] == 0 for r in rows),
            "empty_pools_where_radial_verifies": sum(
                r["found"] == 0 and r["radial"]["verified"] > 0 for r in rows
            ),
            "wall_s_median": round(float(np.median(walls)), 3),
            "wall_s_p90": round(float(np.quantile(walls, 0.9)), 3),
        },
        "load_average": {"start": load_start, "end": os.getloadavg()},
        "trials": rows,
    }
    path = RESULTS / f"{NAME}.json"
    old = json.loads(path.read_text()) if path.is_file() else {}
    labels = {k: v for k, v in old.get("labels", {}).items() if k != args.label}
    labels[args.label] = block
    classification = {label: classify(b) for label, b in labels.items()}
    notes = {"notes": old["notes"]} if "notes" in old else {}  # what each label ran on, written by hand
    report(NAME, {"labels": labels, "empty_pool_classification": classification, **notes}, seeds=SeedSplit(dev=DEV_SEEDS, held_out=HELD_OUT), split="dev",
           used_seeds=args.seeds)  # fmt: skip


if __name__ == "__main__":
    main()
