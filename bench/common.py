"""Shared helpers for the benchmarks: timing and result reporting (files with provenance)."""

from __future__ import annotations

import atexit
import importlib.util
import json
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from baseplace.errors import InputError
from baseplace_experiments.results import RunClock, write_results

RESULTS = Path(__file__).parent / "results"


def _one_line_input_errors(kind: type[BaseException], error: BaseException, tb: object) -> None:
    """A benchmark refused for bad input (a protocol not committed ...) says so in one line, exit 2."""
    if issubclass(kind, InputError):
        sys.stderr.write(f"error: {error}\n")
        sys.exit(2)
    sys.__excepthook__(kind, error, tb)  # type: ignore[arg-type]


sys.excepthook = _one_line_input_errors
STARTED = RunClock()
"""Started when a benchmark imports this module, before its work: the run's wall time."""


def other_module(root: Path, relative: str, name: str) -> ModuleType:
    """The module ``baseplace/<relative>`` of the checkout at ``root``, loaded under ``name`` for a paired bench.

    Loaded from a copy in a temporary folder: numba keeps its compiled functions beside the source
    file, under the name they were loaded with, so a module loaded from the checkout itself under
    another name would leave that checkout's cache unloadable by its own package.
    """
    path = root / "src" / "baseplace" / relative
    if not path.is_file():
        sys.stderr.write(f"error: no {relative} at {path}: --other must be a checkout's root\n")
        raise SystemExit(2)
    folder = tempfile.mkdtemp(prefix="paired_")
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    copy = Path(folder) / path.name
    shutil.copyfile(path, copy)
    spec = importlib.util.spec_from_file_location(name, copy)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def reaches(robot: Any, arm: Any, q: Any, T: Any, data: Any = None) -> bool:
    """Whether pinocchio's FK puts the TCP of arm joint values ``q`` (n,) within the IK's tolerances
    (1e-4 m, 1e-3 rad) of ``T`` (4, 4), both in the arm's base frame: the oracle of the IK benches.

    ``data``: a ``robot.model.createData()`` to reuse (a new one if None).
    """
    import pinocchio as pin

    model = robot.model
    data = model.createData() if data is None else data
    pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
    base, tcp = model.getFrameId(arm.base_frame), model.getFrameId(arm.tcp_frame)
    reached = (data.oMf[base].inverse() * data.oMf[tcp]).homogeneous
    rot = np.arccos(np.clip((np.trace(reached[:3, :3].T @ T[:3, :3]) - 1) / 2, -1, 1))
    return bool(np.linalg.norm(reached[:3, 3] - T[:3, 3]) < 1e-4 + 1e-9 and rot < 1e-3 + 1e-9)


def median_time(fn: Callable[[], Any], repeats: int = 5) -> float:
    """Median wall time [s] of ``repeats`` calls (the machine is shared and noisy)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def alternated(turns: int, prepare: Callable[[str], Callable[[], Any]], sides: tuple[str, str] = ("this", "other")
               ) -> tuple[dict[str, float], dict[str, Any]]:  # fmt: skip
    """The two sides of a paired bench take turns, ``turns`` times each, alternately.

    Each turn ``prepare(side)`` readies the side (not timed) and returns the work to time. The
    first turn of each side is not counted (caches). Returns per side the fastest counted wall
    time [ms] and the answer of its last turn.
    """
    fastest = dict.fromkeys(sides, np.inf)
    answer: dict[str, Any] = {}
    for turn in range(2 * turns):
        side = sides[turn % 2]
        work = prepare(side)
        t = time.perf_counter()
        answer[side] = work()
        if turn >= 2:
            fastest[side] = min(fastest[side], (time.perf_counter() - t) * 1e3)
    return fastest, answer


def ratio_summary(ms: dict[str, list[float]]) -> dict[str, Any]:
    """Two sides' times [ms] over the same inputs (``ms``: the side first named, then the other): medians, means, the per-input ratio's median and quartiles."""
    (first, a), (second, b) = ((k, np.array(v)) for k, v in ms.items())
    ratio = a / b
    return {
        "median_ms": {first: float(np.median(a)), second: float(np.median(b))},
        "mean_ms": {first: float(a.mean()), second: float(b.mean())},
        "ratio_median": float(np.median(ratio)),
        "ratio_quartiles": [float(x) for x in np.quantile(ratio, [0.25, 0.75])],
    }


def report(name: str, result: dict[str, Any], **provenance: Any) -> None:
    """Print a result and store it whole as bench/results/NAME.json, with its provenance.

    Keyword arguments go to :func:`baseplace_experiments.results.provenance` (seeds, split, protocol ...).
    """
    RESULTS.mkdir(exist_ok=True)
    whole = write_results(RESULTS / f"{name}.json", {"benchmark": name, **result}, STARTED, **provenance)
    print(json.dumps(whole, indent=2))
