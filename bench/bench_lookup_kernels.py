"""The map lookups' compile time on a cold start and their run time (``ReachabilityMap``'s kernels).

Compile: a fresh interpreter with an empty numba cache (``NUMBA_CACHE_DIR`` in a temporary
folder) loads the map and times the first call of each lookup (serial and parallel batch,
serial and parallel plane, one pose), which compiles it; the sum is what a cold start (a fresh
CI machine) pays for them. Run time: in this process, once compiled, the median of
``--repeat`` calls of each: ``inverse`` of 100 000, 10 000 and 1 000 base poses, ``inverse_on_plane``
of as many, and ``value`` of one pose (median of 20 000 calls, in microseconds).
Threads: as numba is configured (``NUMBA_NUM_THREADS``).

To compare two versions, run it with each first on ``PYTHONPATH`` (``<checkout>/src:bench``),
alternating them on the same map; ``library`` records which ran. Stored as bench/results/NAME.json.

Usage: python bench/bench_lookup_kernels.py --map tiago.rmap [--repeat 15] [--no-compile] [--name lookup_kernels]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from common import median_time, report
from find_rate import library_commit

FIRST_CALLS = """
import json, sys, time
import numpy as np
from baseplace.reachability.storage import load_map
rmap = load_map(sys.argv[1]); rmap.tables
rng = np.random.default_rng(0)
target = np.eye(4); target[:3, 3] = (0.6, 0.0, 0.8)
out = {}
for name, n in (("batch_serial", 10), ("batch_parallel", 4096)):
    bases = np.tile(np.eye(4), (n, 1, 1)); bases[:, :2, 3] = rng.uniform(-1, 1, (n, 2))
    t = time.perf_counter(); rmap.inverse(target, bases); out[name] = time.perf_counter() - t
for name, n in (("plane_serial", 10), ("plane_parallel", 4096)):
    t = time.perf_counter()
    rmap.inverse_on_plane(target, rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n), (0, 0, 1), 0.0)
    out[name] = time.perf_counter() - t
t = time.perf_counter(); rmap.value(target); out["one_pose"] = time.perf_counter() - t
print(json.dumps(out))
"""


def compile_times(map_path: str) -> dict[str, float]:
    """Seconds of each lookup's first call in a fresh interpreter with an empty numba cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", FIRST_CALLS, map_path], capture_output=True, text=True,
                             env=env, check=True)  # fmt: skip
    times = json.loads(out.stdout.strip().splitlines()[-1])
    return {**times, "total": sum(times.values())}


def run_times(map_path: str, repeat: int) -> dict[str, float]:
    from baseplace.geometry.poses import BasePose
    from baseplace.reachability.storage import load_map

    rmap = load_map(map_path)
    rng = np.random.default_rng(1)
    target = np.eye(4)
    target[:3, 3] = (0.6, 0.0, 0.8)  # a side grasp 0.8 m high, bases around it
    out = {}
    for n in (100_000, 10_000, 1_000):
        gamma = rng.uniform(-np.pi, np.pi, n)
        xy = rng.uniform(-0.5, 1.7, (n, 2))
        bases = BasePose.batch_matrix(np.column_stack([xy, gamma]))
        rmap.inverse(target, bases)
        out[f"inverse_{n}_ms"] = median_time(lambda b=bases: rmap.inverse(target, b), repeat) * 1e3
        rmap.inverse_on_plane(target, xy, gamma, (0, 0, 1), 0.0)
        out[f"plane_{n}_ms"] = (
            median_time(lambda xy=xy, g=gamma: rmap.inverse_on_plane(target, xy, g, (0, 0, 1), 0.0), repeat)
            * 1e3
        )
        out[f"reached_share_{n}"] = float(np.mean(rmap.inverse(target, bases) > 0))
    T = np.linalg.inv(bases[0]) @ target
    calls = 20_000
    rmap.value(T)
    t = time.perf_counter()
    for _ in range(calls):
        rmap.value(T)
    out["value_one_us"] = (time.perf_counter() - t) / calls * 1e6
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", required=True, help="a reachability map file (.rmap)")
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--no-compile", action="store_true", help="skip the cold compile (minutes)")
    parser.add_argument("--name", default="lookup_kernels", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    import numba

    result: dict[str, object] = {
        "library": library_commit(),
        "numba_threads": numba.config.NUMBA_NUM_THREADS,
        "map": os.path.basename(args.map),
        "repeat": args.repeat,
    }
    if not args.no_compile:
        result["compile_s"] = compile_times(args.map)
    result["run"] = run_times(args.map, args.repeat)
    report(args.name, result)


if __name__ == "__main__":
    main()
