"""Where a warm ``place`` query spends its time outside the motion check (issue 25; development only).

Runs ``bench_warm_place.py``'s queries in process (its scenes, its side grasp, ``place_job`` with
the service's defaults and one :class:`SceneCache` per scene, so every counted query is warm), with
no HTTP in between. Per query it records the placements (pose, joints, robustness) and the
rejections (failures, contacts), so that two library checkouts can be compared verdict for verdict
(``--compare A B``: two results files of this script), the ``timings_ms`` medians and the CPU
time of each query (``cpu_ms``, the process's, with ``NUMBA_NUM_THREADS=1``: less sensitive than wall
time to other processes on a shared machine).
``--cprofile``: cProfile the counted queries and print the top functions (cumulative and own time).

Usage: python bench/profile_warm_place.py [--queries 5] [--name warm_profile] [--cprofile]
       python bench/profile_warm_place.py --compare NAME_A NAME_B
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import time
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.jobs.inputs import CloudInput
from baseplace.jobs.place import PlaceJob, place_job
from baseplace.jobs.report import NoResultError
from baseplace.placement.pipeline import PlaceSettings, with_floor
from baseplace.placement.scene_cache import SceneCache
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import TableGridSettings
from bench_warm_place import CELLS, GRASP, SEEDS, pose_text
from common import report

RESULTS = Path(__file__).parent / "results"


def verdict(answer: dict[str, Any]) -> dict[str, Any]:
    """What must not change between two checkouts: the placements and the rejections."""
    rows = [
        {k: p.get(k) for k in ("x", "y", "yaw", "joints", "robustness", "reachability")}
        for p in answer.get("placements", [])
    ]
    return {"placements": rows, "tries": answer.get("tries"), "collisions": answer.get("collisions"),
            "failures": answer.get("failures")}  # fmt: skip


def run(args: argparse.Namespace) -> None:
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    s = TableGridSettings()
    profile = cProfile.Profile() if args.cprofile else None
    rows = []
    for seed in SEEDS if args.scene is None else (args.scene[0],):
        for cell in CELLS if args.scene is None else (tuple(args.scene[1:]),):
            _, p_est, seen = trial_scene(seed, cell, s)
            points = with_floor(seen, 0.0)
            cache = SceneCache(points)
            target = pose_text(s.grasps(p_est)[GRASP])
            for q in range(args.queries + 1):
                job = PlaceJob([target], robot, cloud=CloudInput(points=points), map=rmap,
                               settings=PlaceSettings(), seed=q, cache=cache)  # fmt: skip
                if profile is not None and q > 0:
                    profile.enable()
                cpu = time.process_time()
                try:
                    answer = place_job(job).to_json()
                except NoResultError as e:
                    answer = e.report.to_json()
                cpu_ms = (time.process_time() - cpu) * 1e3
                if profile is not None and q > 0:
                    profile.disable()
                if q > 0:
                    rows.append({"seed": seed, "cell": list(cell), "query": q,
                                 "timings_ms": answer.get("timings_ms", {}), "cpu_ms": round(cpu_ms, 2),
                                 **verdict(answer)})  # fmt: skip
            print(seed, cell, rows[-1]["timings_ms"].get("request_to_placement"), flush=True)
    keys = ("request_to_placement", "motion", "robustness", "osrm", "query")
    medians = {k: float(np.median([r["timings_ms"].get(k, np.nan) for r in rows])) for k in keys}
    medians["cpu"] = float(np.median([r["cpu_ms"] for r in rows]))
    print(medians, "found", sum(bool(r["placements"]) for r in rows), "of", len(rows))
    report(args.name, {"medians_ms": medians, "rows": rows})
    if profile is not None:
        for key in ("cumulative", "tottime"):
            pstats.Stats(profile).sort_stats(key).print_stats(40)


def compare(a: str, b: str) -> None:
    rows_a = json.loads((RESULTS / f"{a}.json").read_text())["rows"]
    rows_b = json.loads((RESULTS / f"{b}.json").read_text())["rows"]
    same = 0
    for ra, rb in zip(rows_a, rows_b, strict=True):
        keys = ("placements", "tries", "collisions", "failures")
        if all(ra[k] == rb[k] for k in keys):
            same += 1
        else:
            print("differs:", ra["seed"], ra["cell"], ra["query"], [k for k in keys if ra[k] != rb[k]])
    print(f"{same} of {len(rows_a)} queries identical")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--queries", type=int, default=5, help="counted warm queries per scene")
    parser.add_argument("--name", default="warm_profile", help="results file bench/results/NAME.json")
    parser.add_argument("--cprofile", action="store_true", help="cProfile the counted queries")
    parser.add_argument("--scene", type=int, nargs=3, metavar=("SEED", "CX", "CY"), help="this scene only")
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two results files")
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
    else:
        run(args)


if __name__ == "__main__":
    main()
