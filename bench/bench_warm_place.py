"""Issue 25's warm-query figure: ``baseplace serve``, a table scene, a side grasp, the defaults.

What one warm ``POST /place`` costs with the product's defaults (reaching-motion check and the
64-draw robustness score), request in to JSON out, on the scenes an engineer meets first: seed
004's table with a bottle on it, scanned with 3 mm noise, plus the floor the robot stands on.

* Scenes: ``baseplace_experiments.execution_experiment.trial_scene`` (table-grid dev seeds
  :data:`SEEDS`, cells :data:`CELLS`; none of the held-out seeds of any protocol), the noisy cloud
  with a floor at z = 0 (``with_floor``), uploaded once each to one service on loopback.
* Query: one target, a side grasp of the bottle at the robot's *estimate*
  (``TableGridSettings.grasps``, index :data:`GRASP`), ``tries`` and everything else at the
  service's defaults; ``--queries`` per scene with seeds 1..N after one warm-up query (seed 0)
  that is not counted (it builds the scene's collision model and compiles nothing new).
* Reported per setting (defaults; the seed-000 checks only, ``no_motion_check`` and
  ``robustness_samples 0``): the server's own time (``x-server-time-ms``) median and p90, the
  JSON's ``timings_ms`` (``request_to_placement``, ``motion``, ``robustness``) medians, and how
  many queries found a placement. Compare two library checkouts by running this script with each
  first on ``PYTHONPATH`` (``PYTHONPATH=<checkout>/src:bench``), back to back on the same machine;
  ``library`` records the commit that ran, ``provenance`` this script's.

Usage: python bench/bench_warm_place.py [--queries 10] [--name warm_place]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from baseplace.geometry.poses import matrix_to_rpy
from baseplace.placement.pipeline import with_floor
from baseplace.terrain.io import Cloud, save_cloud
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import TableGridSettings
from bench_serve import UPLOAD, pct, start_server, wait_healthy
from common import report
from find_rate import library_commit

SEEDS = (0, 1, 2)
CELLS = ((0, 0), (2, 0))
GRASP = 4
"""A side grasp (0-15 are side grasps, 16-31 top-down) that bench_motion_verdicts also uses."""
SETTINGS = {"defaults": {}, "seed000": {"no_motion_check": True, "robustness_samples": 0}}


def pose_text(T: np.ndarray) -> str:
    """'x y z roll pitch yaw' of a (4, 4) pose."""
    return " ".join(f"{v:.5f}" for v in (*T[:3, 3], *matrix_to_rpy(T[:3, :3])))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--queries", type=int, default=10, help="counted warm queries per scene and setting")
    parser.add_argument("--name", default="warm_place", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    s = TableGridSettings()
    env = dict(os.environ)  # the service runs the checkout this script's PYTHONPATH names
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in SETTINGS}
    with tempfile.TemporaryDirectory() as tmp:
        server, url, _ = start_server(env, 120.0)
        try:
            with httpx.Client(base_url=url, timeout=300.0) as http:
                started_s = wait_healthy(http, server, 600.0)
                for seed in SEEDS:
                    for cell in CELLS:
                        _, p_est, seen = trial_scene(seed, cell, s)
                        path = Path(tmp) / f"table_{seed}_{cell[0]}{cell[1]}.ply"
                        save_cloud(Cloud(with_floor(seen, 0.0), source="bench_warm_place"), path)
                        r = http.post(
                            "/scenes", params={"format": "ply"}, content=path.read_bytes(), headers=UPLOAD
                        )
                        r.raise_for_status()
                        scene_id = r.json()["scene_id"]
                        target = pose_text(s.grasps(p_est)[GRASP])
                        for name, extra in SETTINGS.items():
                            for q in range(args.queries + 1):
                                body = {"scene_id": scene_id, "targets": [target], "seed": q, **extra}
                                t0 = time.perf_counter()
                                r = http.post("/place", json=body)
                                wall_ms = (time.perf_counter() - t0) * 1e3
                                answer = r.json()
                                row = {"seed": seed, "cell": list(cell), "query": q, "status": r.status_code,
                                       "server_ms": float(r.headers.get("x-server-time-ms", "nan")),
                                       "wall_ms": round(wall_ms, 1),
                                       "found": bool(answer.get("placements")) if r.status_code == 200 else False,
                                       "timings_ms": answer.get("timings_ms", {})}  # fmt: skip
                                if q > 0:
                                    rows[name].append(row)
                            last = rows[name][-1]
                            print(
                                seed, cell, name, last["status"], last["server_ms"], last["found"], flush=True
                            )
        finally:
            server.terminate()
            server.wait(30)

    def summary(found: list[dict[str, Any]]) -> dict[str, Any]:
        def med(key: str) -> float:
            values = [r["timings_ms"][key] for r in found if key in r["timings_ms"]]
            return pct(values, 50)

        server_ms = [r["server_ms"] for r in found]
        return {"queries": len(found), "found": sum(r["found"] for r in found),
                "server_ms_median": pct(server_ms, 50), "server_ms_p90": pct(server_ms, 90),
                "request_to_placement_ms_median": med("request_to_placement"),
                "motion_ms_median": med("motion"), "robustness_ms_median": med("robustness")}  # fmt: skip

    result = {
        "library": library_commit(),  # the baseplace that ran (the service too: the same PYTHONPATH)
        "scenes": f"table-grid dev seeds {list(SEEDS)}, cells {[list(c) for c in CELLS]}, 3 mm noise, floor at z = 0",
        "query": f"one side grasp (TableGridSettings.grasps index {GRASP}) at the estimate, service defaults",
        "service_start_s": started_s,
        "summary": {name: summary(r) for name, r in rows.items()},
        "rows": rows,
    }
    for name, row in result["summary"].items():
        print(name, row)
    report(args.name, result)


if __name__ == "__main__":
    main()
