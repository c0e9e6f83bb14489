"""The reaching motions of found dev placements, checked on the true scene along their whole path.

Development data only (find_rate's dev seeds 25000-25059; the held-out seeds are refused): for each
seed, ``place`` as ``bench/find_rate.py`` calls it, every reaching motion ``MotionChecker.check``
returned recorded, and for each placement found its motion (the transit ``path`` and the straight
``approach``) checked with the find-rate oracle (coal on the true shapes, the floor against every
geometry the arm's first revolute joint moves) at ``--states`` states per joint line. The hand may
touch the grasped bottle on the approach only.

Usage: python bench/find_rate_motion_path.py --out x.json [--seeds 25005 ...] [--states 60]
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import itertools
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.placement.motion import MotionChecker
from baseplace.robots.model import Robot
from find_rate import Oracle, library_commit, make_scene, run_place

DEV = range(25000, 25060)


def _path_contacts(oracle: Oracle, motion: Any, T: np.ndarray, scene: Any, states: int) -> dict[str, Any]:
    """Per stage, the contacts that count at ``states`` states per joint line, and the states checked."""
    out: dict[str, Any] = {"checked_states": 0, "contacts": []}
    for stage, waypoints in (("transit", motion.path), ("approach", motion.approach)):
        for w, (a, b) in enumerate(itertools.pairwise(np.asarray(waypoints, dtype=float))):
            for f in np.linspace(0.0, 1.0, states):
                out["checked_states"] += 1
                touched = oracle.contacts(a + f * (b - a), T, scene, first=False)
                counting = oracle.counting(touched)
                if stage == "transit":  # the hand on the bottle counts there: nothing may be touched
                    counting = touched
                for c in counting:
                    out["contacts"].append({"stage": stage, "line": w, "f": round(float(f), 3), "contact": c})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seeds", type=int, nargs="*", default=[25005])
    ap.add_argument("--states", type=int, default=60)
    args = ap.parse_args(argv)
    if any(s not in DEV for s in args.seeds):
        ap.error("development seeds only: 25000-25059")
    robot = Robot("tiago")
    oracle = Oracle(robot)
    recorded: list[tuple[np.ndarray, Any]] = []
    original = MotionChecker.check

    def check(self: MotionChecker, q_grasp: Any, T_world_base: Any, T_world_tcp: Any, seed: int = 0) -> Any:
        motion = original(self, q_grasp, T_world_base, T_world_tcp, seed)
        if motion is not None:
            recorded.append((np.asarray(T_world_base, dtype=float).copy(), motion))
        return motion

    MotionChecker.check = check  # type: ignore[method-assign]
    rows = []
    for seed in args.seeds:
        scene = make_scene(seed)
        recorded.clear()
        t0 = time.perf_counter()
        method = run_place(scene, oracle)
        row: dict[str, Any] = {"seed": seed, "kind": scene.kind, "found": method["found"],
                               "seconds": round(time.perf_counter() - t0, 2), "placements": []}  # fmt: skip
        if not method["found"]:
            row["refusal"] = method.get("refusal")
        for p in method.get("placements", []):
            x, y, yaw = p["base"]
            match = [(T, m) for T, m in recorded
                     if np.allclose(T[:2, 3], [x, y], atol=1e-3)
                     and abs(np.arctan2(T[1, 0], T[0, 0]) - yaw) < 1e-3]  # fmt: skip
            entry: dict[str, Any] = {"base": p["base"], "touches_at_grasp": p["touches"]}
            if not match:
                entry["motion"] = "not recorded"
            else:
                T, motion = match[-1]
                entry.update(_path_contacts(oracle, motion, T, scene, args.states))
                entry["waypoints"] = [len(motion.path), len(motion.approach)]
            row["placements"].append(entry)
        rows.append(row)
        print(
            seed,
            scene.kind,
            row["found"],
            [len(e.get("contacts", [])) for e in row["placements"]],
            flush=True,
        )
    summary = {
        "scenes": len(rows),
        "found": sum(r["found"] for r in rows),
        "motions_touching_true_scene": sum(bool(e.get("contacts")) for r in rows for e in r["placements"]),
        "floor_contacts": sum(
            "floor" in c["contact"] for r in rows for e in r["placements"] for c in e.get("contacts", [])
        ),
    }
    args.out.write_text(json.dumps({"benchmark": "find_rate_motion_path", "states_per_line": args.states,
                                     "summary": summary, "scenes": rows, "library": library_commit()},
                                    indent=1) + "\n")  # fmt: skip
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
