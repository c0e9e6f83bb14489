"""Cold start (issue 18): ``import baseplace`` and ``baseplace place`` from a new process, caches warm.

The generated 10 x 10 m scene of bench_serve (seed 1: floor + two inclined planes, three support
regions) and one top-down target; the default map, numba's kernels and the cloud's segmentation
(terrain.cache) already cached (one unmeasured run first). Each figure is the median of
``--runs`` new processes: wall time and CPU time (user + system, the machine is shared). ``--baseline-src DIR`` runs the same commands with
another source tree first on the path (e.g. the commit before), for the ratio in the same run,
and the placements both print are compared (a cache must not change the answer).

Usage: nice -n 10 python bench/bench_cold_start.py [--runs 5] [--baseline-src ../main/src]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.io import Cloud, save_cloud
from common import report


def timed(cmd: list[str], env: dict[str, str]) -> tuple[float, float, int, str]:
    """Wall and CPU time [s] of one new process, its exit code and its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.returncode, done.stdout


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--baseline-src", default=None)
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    scene = generate_scene(SceneSettings(n_planes=2, extent=(10.0, 10.0)), rng)
    cloud = Path(tempfile.mkdtemp(prefix="bench-cold-")) / "scene1.ply"
    save_cloud(Cloud(scene.sample_cloud(rng), source="bench_cold_start"), cloud)
    plane = scene.planes[2]
    cx, cy = plane.center
    target = f"{cx:.3f} {cy:.3f} {float(plane.z(np.array([[cx, cy]]))[0]) + 0.75:.3f} 0 1.5708 0"
    here = str(Path(__file__).resolve().parents[1] / "src")
    trees = {"this": here} | (
        {"baseline": str(Path(args.baseline_src).resolve())} if args.baseline_src else {}
    )
    place = [
        sys.executable,
        "-m",
        "baseplace.cli",
        "place",
        "--cloud",
        str(cloud),
        "--target",
        target,
        "--stand-on",
        "any",  # the target is over a raised plane: the robot stands on it (not the default, ground)
        "--json",
    ]
    commands = {
        "import baseplace": [sys.executable, "-c", "import baseplace"],
        "place (IK + collision checks)": [*place, "--no-motion-check", "--robustness-samples", "0"],
        "place (defaults)": place,
    }
    result: dict[str, Any] = {"scene": "generated 10 x 10 m, 3 support regions, seed 1", "target": target,
                              "runs": args.runs, "load_average_at_start": os.getloadavg()[0]}  # fmt: skip
    placements: dict[tuple[str, str], str] = {}
    for tree, src in trees.items():
        env = dict(os.environ, PYTHONPATH=src)
        for name, cmd in commands.items():
            timed(cmd, env)  # caches warm: the map, numba's kernels, the bytecode
            runs = [timed(cmd, env) for _ in range(args.runs)]
            assert all(code in (0, 3) for _, _, code, _ in runs), (tree, name, runs)
            result[f"{tree}: {name}"] = {
                "wall_s_median": round(float(np.median([w for w, *_ in runs])), 3),
                "cpu_s_median": round(float(np.median([c for _, c, *_ in runs])), 3),
                "wall_s": [round(w, 3) for w, *_ in runs],
            }
            if name.startswith("place"):
                answers = {json.dumps(json.loads(out)["placements"]) for *_, out in runs}
                assert len(answers) == 1, (tree, name, "placements differ between runs")
                placements[(tree, name)] = answers.pop()
            print(tree, name, result[f"{tree}: {name}"], flush=True)
    if args.baseline_src:
        for name in commands:
            a, b = result[f"this: {name}"], result[f"baseline: {name}"]
            result[f"ratio baseline/this: {name}"] = {
                "wall": round(b["wall_s_median"] / a["wall_s_median"], 2),
                "cpu": round(b["cpu_s_median"] / a["cpu_s_median"], 2),
            }
            if name.startswith("place"):
                result[f"same placements as baseline: {name}"] = (
                    placements[("this", name)] == placements[("baseline", name)]
                )
    result["load_average_at_end"] = os.getloadavg()[0]
    result["goals"] = (
        "import baseplace <= 0.3 s; baseplace place from a new process <= 1.5 s wall, caches warm"
    )
    report("cold_start", result, used_seeds=[1], protocol=__doc__.split("\n\n")[1])


if __name__ == "__main__":
    main()
