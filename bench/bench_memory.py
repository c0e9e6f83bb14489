"""Peak memory (RSS) of the two biggest jobs, each in a child process of its own; target <= 4 GB.

(a) ``baseplace build-map --samples 5e7`` of TIAGo (the CLI, as a user runs it);
(b) ``terrain_from_points`` on a ~1e7-point cloud of a generated 40 m x 40 m scene (4 large planes,
25 mm noise, 12.5 mm spacing), with the RSS of a child that only loads the cloud as a baseline.

The peak is measured two ways: polling the RSS of the child and its descendants every 50 ms
(psutil), and the kernel's ``ru_maxrss`` of that one child (``os.wait4``), which catches spikes
shorter than the polling interval. Linux starts a child's ``ru_maxrss`` at its parent's RSS at
fork time, so this process stays small: it never imports baseplace, and the cloud is generated
in a child too. MB are 10^6 bytes.
Usage: python bench/bench_memory.py [--samples 5e7] [--extent 40] [--keep-tmp]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from common import report

TARGET_MB = 4000
BASEPLACE = str(Path(sys.executable).with_name("baseplace"))


def peak_rss(cmd: list[str], poll_s: float = 0.05) -> dict[str, Any]:
    """Run ``cmd`` to completion; its peak RSS [MB] (polled, with descendants, and ru_maxrss)."""
    start = time.perf_counter()
    out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()  # files: pipes could fill up and block
    proc = subprocess.Popen(cmd, stdout=out, stderr=err)
    peak = 0
    stop = threading.Event()

    def poll() -> None:
        nonlocal peak
        try:
            root = psutil.Process(proc.pid)
            while not stop.is_set():
                total = 0
                for p in [root, *root.children(recursive=True)]:
                    try:
                        total += p.memory_info().rss
                    except psutil.NoSuchProcess:
                        pass
                peak = max(peak, total)
                stop.wait(poll_s)
        except psutil.NoSuchProcess:
            return

    watcher = threading.Thread(target=poll, daemon=True)
    watcher.start()
    _, status, usage = os.wait4(proc.pid, 0)  # the rusage of this child alone
    proc.returncode = os.waitstatus_to_exitcode(status)
    stop.set()
    watcher.join()
    out.seek(0)
    err.seek(0)
    stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[:3]} failed ({proc.returncode}): {stderr[-2000:]}")
    return {
        "peak_rss_polled_mb": round(peak / 1e6, 1),
        "ru_maxrss_mb": round(usage.ru_maxrss * 1024 / 1e6, 1),  # Linux reports KiB
        "wall_s": round(time.perf_counter() - start, 1),
        "stdout_tail": stdout.strip()[-300:],
    }


GENERATE = """
import sys, numpy as np
from baseplace.sim.scenes import SceneSettings, generate_scene
rng = np.random.default_rng(11)
extent = float(sys.argv[2])
scene = generate_scene(SceneSettings(size_class="large", n_planes=4, extent=(extent, extent)), rng)
np.save(sys.argv[1], scene.sample_cloud(rng), allow_pickle=False)
"""

SEGMENT = """
import sys, numpy as np
points = np.load(sys.argv[1])
if sys.argv[2] == "segment":
    from baseplace.terrain.pipeline import terrain_from_points
    terrain = terrain_from_points(points)
    print(len(points), "points,", len(terrain.graph), "regions", terrain.timings_ms)
else:
    import baseplace.terrain.pipeline  # same imports, no work
    print(len(points), "points loaded")
"""


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", default="5e7")
    parser.add_argument("--extent", type=float, default=40.0, help="scene side [m]; 40 m gives ~1e7 points")
    parser.add_argument("--keep-tmp", action="store_true")
    args = parser.parse_args()
    result: dict[str, Any] = {
        "cores": os.cpu_count(),
        "total_memory_mb": round(psutil.virtual_memory().total / 1e6),
    }
    tmp = tempfile.mkdtemp(prefix="bench_memory_")
    try:
        out = Path(tmp) / "tiago.rmap"
        build = peak_rss([BASEPLACE, "build-map", "--robot", "tiago", "--samples", args.samples,
                          "--out", str(out), "--json"])  # fmt: skip
        build["stdout_tail"] = build["stdout_tail"].replace(tmp, "TMP")  # no path of this machine in results
        result["build_map"] = {"samples": float(args.samples), **build}
        cloud = Path(tmp) / "cloud.npy"
        subprocess.run([sys.executable, "-c", GENERATE, str(cloud), str(args.extent)], check=True)
        n_points = int(np.load(cloud, mmap_mode="r").shape[0])
        baseline = peak_rss([sys.executable, "-c", SEGMENT, str(cloud), "load"])
        segment = peak_rss([sys.executable, "-c", SEGMENT, str(cloud), "segment"])
        result["segmentation"] = {
            "points": n_points,
            "scene": f"{args.extent:g} m x {args.extent:g} m, 4 large planes, sigma 25 mm, spacing 12.5 mm",
            **segment,
            "load_only_peak_rss_mb": baseline["peak_rss_polled_mb"],
            "load_only_ru_maxrss_mb": baseline["ru_maxrss_mb"],
        }
    finally:
        if not args.keep_tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    worst = max(result["build_map"]["ru_maxrss_mb"], result["segmentation"]["ru_maxrss_mb"])
    result["target"] = f"peak RSS <= {TARGET_MB} MB"
    result["within_target"] = bool(worst <= TARGET_MB)
    report("memory", result)


if __name__ == "__main__":
    main()
