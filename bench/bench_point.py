"""Latency of ``baseplace point`` per frame: load, landmarks, gesture, objects, selection (issue 30).

Usage: ``python bench/bench_point.py [--frames N] [--results FILE.json]``. Frames are the pointing
experiment's development scenes (640x480, docs/protocols/pointing.md), written as files and run
through the ``point`` job with ``--landmarks`` (the landmarks step reads the JSON: MediaPipe's own
time is not in it). Medians and 90th percentiles in milliseconds.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile

import numpy as np

from baseplace.jobs.point import PointJob, point_job
from baseplace.jobs.report import NoResultError
from baseplace.sim.pointing_scenes import generate_pointing_scene, save_pointing_scene
from baseplace_experiments.pointing_experiment import SEEDS
from baseplace_experiments.results import RunClock, write_results

STEPS = ("load", "landmarks", "gesture", "objects", "selection", "total")


def main(argv: list[str] | None = None) -> int:
    """Time the frames, print and write the medians."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--results", default=None)
    args = parser.parse_args(argv)
    clock = RunClock()
    seeds = list(SEEDS.dev[: args.frames])
    timings: dict[str, list[float]] = {s: [] for s in STEPS}
    for seed in seeds:
        with tempfile.TemporaryDirectory() as folder:
            f = save_pointing_scene(generate_pointing_scene(seed), folder)
            try:
                report = point_job(
                    PointJob(f["rgb"], f["depth"], f["intrinsics"], f["transform"], f["landmarks"])
                )
            except NoResultError as exc:
                report = exc.report
        t = report.to_json()["timings_ms"]
        for step in STEPS:
            if step in t:
                timings[step].append(t[step])
    summary = {s: {"median_ms": float(np.median(v)), "p90_ms": float(np.percentile(v, 90)), "frames": len(v)}
               for s, v in timings.items() if v}  # fmt: skip
    result = {"image": "640x480", "summary": summary}
    print(json.dumps(result, indent=1))
    if args.results:
        write_results(args.results, result, clock, seeds=SEEDS, split="dev", used_seeds=seeds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
