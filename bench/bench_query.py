"""Single-pose and batched map queries on a loaded machine, and the memory a loaded map takes.

Load: one busy-loop process per core (same niceness as this process: another program competing
for the CPU at equal priority), started before and stopped after the timed loops. Single-pose
rate: calls of ``ReachabilityMap.value`` (the single-pose query) and ``reachability``
with one (4, 4) pose and of ``inverse`` with one
base pose, each repeated for ``--seconds``; median of 3 runs. The random pose mostly falls outside
the reached cells; ``value`` is also timed on a pose in a reached cell (the FK pose of a random
configuration, where the support test reads the cells around it) and on a pose in a cell of the
fewest samples (on the boundary, where the test reads more of the 64 neighbours before it is
sure), each also with the map's support test off (same map, same poses). In the same run and under the same load, the parallel kernel forced for
one pose (the behaviour before ``SERIAL_BELOW``) is the baseline. Memory: bytes of the arrays a loaded map holds (``cells``, ``counts``, the dense lookup
``tables``), the bytes allocated and still held after loading and after building the tables
(tracemalloc, which numpy reports to), the peak while building them, and the process's RSS
growth (the map is loaded once before, so the RSS figures exclude the imports' and the
kernels' memory; RSS keeps freed temporaries the allocator did not return).
MB are 10^6 bytes.
Usage: python bench/bench_query.py [--map tiago.rmap] [--seconds 2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import psutil
from scipy.spatial.transform import Rotation

from baseplace.reachability import rmap as rmap_module
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.certify import poses_in_cells
from baseplace.reachability.storage import load_map
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.model import Robot
from common import report

BUSY = "while True: pass"


def rate(call: Callable[[], Any], seconds: float) -> float:
    """Calls per second of ``call`` over about ``seconds`` of wall time."""
    n, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        for _ in range(100):
            call()
        n += 100
    return n / elapsed


def median_rate(call: Callable[[], Any], seconds: float) -> dict[str, float]:
    runs = sorted(rate(call, seconds) for _ in range(3))
    return {"median_per_s": round(runs[1]), "runs_per_s": [round(r) for r in runs]}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--map", default=None)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    robot = Robot("tiago")
    proc = psutil.Process()
    rmap = load_map(args.map, robot) if args.map else build_map(robot, None, BuildSettings())
    del rmap
    rss0 = proc.memory_info().rss
    tracemalloc.start()
    rmap = load_map(args.map, robot) if args.map else build_map(robot, None, BuildSettings())
    held_loaded, _ = tracemalloc.get_traced_memory()
    rss_loaded = proc.memory_info().rss
    tracemalloc.reset_peak()
    offset, blocks = rmap.tables
    held_tables, peak_tables = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_tables = proc.memory_info().rss
    rng = np.random.default_rng(7)
    poses = np.zeros((1000, 4, 4))
    poses[:, :3, :3] = Rotation.random(1000, random_state=rng).as_matrix()
    poses[:, :3, 3] = rng.uniform(-0.6, 0.6, (1000, 3))
    poses[:, 3, 3] = 1.0
    one, target = np.ascontiguousarray(poses[0]), poses[1]
    arm = robot.arm()
    fk = np.ascontiguousarray(forward_kinematics(arm, arm.sample(rng, 1))[0])
    sparse = rmap.cells[rmap.counts == rmap.counts.min()]
    edge = np.ascontiguousarray(poses_in_cells(rmap.grid, sparse[:1], rng)[0])
    whole = rmap.with_support(0, 0.0)
    _ = whole.tables, whole.value(fk)
    base = np.eye(4)[None]
    rmap.value(one)
    rmap.reachability(one)  # compile / load both kernels before timing
    rmap.inverse(target, base)
    rmap.reachability(np.repeat(poses, 10, axis=0))

    def forced_parallel() -> None:
        saved = rmap_module.SERIAL_BELOW
        rmap_module.SERIAL_BELOW = 0
        try:
            rmap.reachability(one)
        finally:
            rmap_module.SERIAL_BELOW = saved

    forced_parallel()
    big = np.ascontiguousarray(np.repeat(poses, 100, axis=0))  # 1e5 poses

    def measure() -> dict[str, Any]:
        return {
            "value_one_pose": median_rate(lambda: rmap.value(one), args.seconds),
            "value_fk_pose": median_rate(lambda: rmap.value(fk), args.seconds),
            "value_fk_pose_support_off": median_rate(lambda: whole.value(fk), args.seconds),
            "value_one_sample_cell_pose": median_rate(lambda: rmap.value(edge), args.seconds),
            "value_one_sample_cell_pose_support_off": median_rate(lambda: whole.value(edge), args.seconds),
            "reachability_one_pose": median_rate(lambda: rmap.reachability(one), args.seconds),
            "inverse_one_base": median_rate(lambda: rmap.inverse(target, base), args.seconds),
            "parallel_kernel_one_pose_baseline": median_rate(forced_parallel, args.seconds),
            "batch_1e5_poses_per_s": round(
                len(big) * median_rate(lambda: rmap.reachability(big), args.seconds)["median_per_s"]
            ),
        }

    idle = measure()
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(os.cpu_count() or 2)]
    try:
        time.sleep(0.5)
        loaded = measure()
    finally:
        for p in busy:
            p.kill()
            p.wait()
    mb = 1e-6
    memory = {
        "cells_counts_MB": round((rmap.cells.nbytes + rmap.counts.nbytes) * mb, 1),
        "lookup_tables_MB": round((offset.nbytes + blocks.nbytes) * mb, 1),
        "held_after_load_MB": round(held_loaded * mb, 1),
        "held_after_tables_MB": round(held_tables * mb, 1),
        "peak_while_building_tables_MB": round(peak_tables * mb, 1),
        "rss_growth_load_MB": round((rss_loaded - rss0) * mb, 1),
        "rss_growth_tables_MB": round((rss_tables - rss_loaded) * mb, 1),
    }
    report(
        "query_tiago",
        {
            "map": {
                "cells_reached": rmap.n_reached,
                "samples": rmap.info.samples,
                "support_count": rmap.info.support_count,
                "support_threshold": rmap.info.support_threshold,
            },
            "cores": os.cpu_count(),
            "busy_processes": len(busy),
            "idle": idle,
            "loaded": loaded,
            "memory": memory,
            "target": "single-pose queries >= 100 k/s with both cores busy",
        },
    )


if __name__ == "__main__":
    main()
