"""A first ``place`` on a real cloud: the PCL mug, as the README runs it, each in a fresh process.

What an engineer waits for when a command line meets a recorded cloud: ``baseplace place`` on
../shared/data's ``table_scene_mug_stereo_textured.pcd`` (z up by the table's normal, a floor
1.25 m down, a side grasp of the mug at its rim; the README's ``--grasp-point`` command) with the
default map from the cache. Nothing is kept between runs: each is a fresh ``python -m
baseplace.cli`` that reads the cloud, finds the mug, builds the scene model and checks the
candidates, and reports its JSON's ``timings_ms`` (``collision_setup``: the scene model around
the object; ``request_to_placement``; ``total``) and the process's wall time.

With ``--baseline SRC`` (another checkout's ``src`` folder) the two libraries run alternately,
``--repeats`` times each, in the same session, and the placements each found are compared (pose,
joints, robustness): the results file gives both medians and their ratio. ``--no-motion`` adds
``--no-motion-check`` (the scene model is then built for the grasp check only).

Usage: python bench/bench_real_cloud_place.py [--baseline OTHER/src] [--repeats 3] [--no-motion]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from common import report

MUG = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "pointclouds"
    / "table_scene_mug_stereo_textured.pcd"
)
ARGS = ["place", "--cloud", str(MUG), "--transform", "0.0162 -0.8378 -0.5458", "--floor", "-1.25",
        "--grasp-point", "0.062 0.608 -0.43 0 0 1.5708", "--json"]  # fmt: skip
STAGES = ("collision_setup", "request_to_placement", "total")


def run_once(src: str, extra: list[str]) -> dict[str, Any]:
    """One fresh ``baseplace place`` with ``src`` first on the path: its timings, wall time and placements."""
    env = {**os.environ, "PYTHONPATH": src, "NUMBA_NUM_THREADS": "1"}
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "baseplace.cli", *ARGS, *extra], capture_output=True,
                          text=True, env=env, check=False)  # fmt: skip
    wall = time.perf_counter() - t
    out = json.loads(proc.stdout)
    placed = [
        {k: p[k] for k in ("x", "y", "yaw", "joints", "robustness") if k in p}
        for p in out.get("placements", [])
    ]
    return {"exit": proc.returncode, "wall_s": round(wall, 3), "placements": placed,
            **{k: out["timings_ms"].get(k) for k in STAGES}}  # fmt: skip


def medians(rows: list[dict[str, Any]]) -> dict[str, float]:
    return {f"{k}_ms": round(statistics.median(r[k] for r in rows), 1) for k in STAGES} | {
        "wall_s": round(statistics.median(r["wall_s"] for r in rows), 2)
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--baseline", default=None, help="another checkout's src folder, run alternately")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-motion", action="store_true", help="add --no-motion-check")
    parser.add_argument("--name", default="real_cloud_place")
    args = parser.parse_args()
    if not MUG.is_file():
        sys.exit(f"error: {MUG.name} is not in ../shared/data/pointclouds")
    extra = ["--no-motion-check"] if args.no_motion else []
    here = str(Path(__file__).resolve().parents[1] / "src")
    libraries = {"this": here} | ({"baseline": args.baseline} if args.baseline else {})
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in libraries}
    for _ in range(args.repeats):
        for name, src in libraries.items():
            rows[name].append(run_once(src, extra))
            print(name, {k: rows[name][-1][k] for k in (*STAGES, "wall_s", "exit")}, flush=True)
    result: dict[str, Any] = {"command": "baseplace " + " ".join([*ARGS[:2], MUG.name, *ARGS[3:], *extra]),
                              "repeats": args.repeats, "medians": {n: medians(r) for n, r in rows.items()}}  # fmt: skip
    if args.baseline:
        head = subprocess.run(
            ["git", "-C", args.baseline, "rev-parse", "HEAD"], capture_output=True, text=True
        )
        result["baseline_commit"] = head.stdout.strip() or None  # None: not a git checkout
        a, b = result["medians"]["this"], result["medians"]["baseline"]
        result["this_over_baseline"] = {k: round(a[k] / b[k], 3) for k in a if b[k]}
        result["same_placements"] = all(
            r["placements"] == s["placements"] for r, s in zip(rows["this"], rows["baseline"], strict=True)
        )
    result["rows"] = rows
    report(args.name, result)


if __name__ == "__main__":
    main()
