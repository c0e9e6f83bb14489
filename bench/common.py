"""Shared helpers for the benchmarks: timing and result reporting."""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).parent / "results"


def median_time(fn: Callable[[], Any], repeats: int = 5) -> float:
    """Median wall time [s] of ``repeats`` calls (the machine is shared and noisy)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def report(name: str, result: dict[str, Any]) -> None:
    """Print a result and store it as bench/results/NAME.json."""
    result = {
        "benchmark": name,
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        **result,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
