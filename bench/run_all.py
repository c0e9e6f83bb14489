"""Run every benchmark (long: several minutes); results land in bench/results/."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent

for script in [
    "bench_build.py",
    "bench_ik.py",
    "bench_irm.py",
    "bench_accuracy.py",
    "bench_segmentation.py",
    "bench_placement.py",
    "bench_surface_map.py",
    "bench_memory.py",
    "bench_serve.py",
    "bench_cold_start.py",
]:
    print(f"== {script}", flush=True)
    subprocess.run([sys.executable, str(HERE / script)], check=True, cwd=HERE)
subprocess.run(
    [sys.executable, str(HERE / "bench_ik.py"), "--robot", "pr2", "--arm", "right"], check=True, cwd=HERE
)
