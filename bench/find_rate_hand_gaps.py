"""How close the hand at the grasp comes to the true table and neighbours, per find-rate scene (analysis only).

The hand is rigid on the TCP, so at the grasp it lies where it lies from every base pose: the
smallest coal distance from its geometries (those the arm's last joint moves) to the true table
and neighbours is a property of the scene, not of a placement. For each scene of a results file of
``bench/find_rate.py`` that its oracle solves, this prints that gap, whether ``place`` found the
scene, and the summary by outcome. It reads the results and regenerates the scenes from their
seeds; it runs no method and changes no verdict, so it may read a held-out results file.

Usage: python bench/find_rate_hand_gaps.py bench/results/find_rate_v2_held_out.json [--out x.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import coal
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.robots.model import Robot
from baseplace_experiments.results import RunClock, write_results
from find_rate import NOISE, Oracle, Scene, make_scene


def hand_gap(oracle: Oracle, scene: Scene) -> tuple[float, str]:
    """The smallest distance [m] from the hand at the grasp to the table or a neighbour, and between what."""
    T_tcp = pose_from_xyz_rpy(scene.grasp) @ np.linalg.inv(oracle.T_tcp_grasp)
    T_world_root = oracle.hand_placed(T_tcp)  # as the oracle's own hand check poses the hand
    obstacles, _, _ = scene.solids()
    best = (np.inf, "")
    for k in sorted(oracle.hand):
        g = oracle.geom.geometryObjects[k]
        T = T_world_root @ oracle.gdata.oMg[k].homogeneous
        Tg = coal.Transform3s(T[:3, :3], T[:3, 3])
        for s in obstacles:
            d = coal.distance(
                g.geometry, Tg, s.geometry, s.transform(), coal.DistanceRequest(), coal.DistanceResult()
            )
            if d < best[0]:
                best = (float(d), f"{oracle.model.frames[g.parentFrame].name} - {s.name}")
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    clock = RunClock()
    data = json.loads(args.results.read_text())
    oracle = Oracle(Robot("tiago"))
    rows: list[dict[str, Any]] = []
    for r in data["scenes"]:
        if not r["oracle"]["found"]:
            continue
        scene = make_scene(r["scene"]["seed"], data["protocol"].get("noise", NOISE))  # the run's noise
        if scene.record() != r["scene"]:
            raise SystemExit(f"scene {scene.seed} differs from the results file's")
        gap, between = hand_gap(oracle, scene)
        rows.append({"seed": scene.seed, "kind": scene.kind, "found": r["method"]["found"],
                     "hand_gap_mm": round(gap * 1e3, 2), "between": between})  # fmt: skip
        print(rows[-1], flush=True)
    summary = {}
    for outcome in (True, False):
        gaps = sorted(x["hand_gap_mm"] for x in rows if x["found"] is outcome)
        summary["found" if outcome else "refused"] = {"scenes": len(gaps), "hand_gap_mm": gaps}
    print(json.dumps(summary, indent=1))
    if args.out is not None:
        write_results(args.out, {"source": args.results.name, "summary": summary, "scenes": rows}, clock)
    return 0


if __name__ == "__main__":
    sys.exit(main())
