"""Building a reachability map by random joint sampling (seed 000, section VI: 5e7 samples).

:func:`build_map` drives the chunked sampling of :mod:`baseplace.reachability.sampling` on this
machine, with resumable checkpoints (``checkpoint.py``) and an atomic save; ``distributed.py``
spreads the same chunks over workers. The map depends only on (robot, arm, grid, samples, seed).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path

from baseplace.errors import InputError
from baseplace.files import output_lock, remove_stray_temporaries
from baseplace.reachability.checkpoint import Checkpoints
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.sampling import CHUNK, MapAccumulator, PartialMap, grid_for, support_count
from baseplace.reachability.settings import DEFAULT_SAMPLES, MAX_SAMPLES, BuildSettings
from baseplace.reachability.storage import load_map, save_map
from baseplace.reachability.support import built_threshold
from baseplace.robots.model import Robot

__all__ = [
    "CHUNK",
    "DEFAULT_CHECKPOINT_EVERY",
    "DEFAULT_CHECKPOINT_EVERY_S",
    "DEFAULT_SAMPLES",
    "MAX_SAMPLES",
    "BuildSettings",
    "MapAccumulator",
    "PartialMap",
    "build_map",
    "grid_for",
    "support_count",
]

# A checkpoint costs ~0.5 s for TIAGo (a pass over the dense counts, ~30 MB written): one per default
# map's worth of samples keeps that to a few percent even on many cores.
DEFAULT_CHECKPOINT_EVERY = 50_000_000

DEFAULT_CHECKPOINT_EVERY_S = 30.0
"""A checkpoint is also written when this much build time [s] has passed since the last one."""


def build_map(
    robot: Robot,
    arm_name: str | None = None,
    settings: BuildSettings | None = None,
    progress: Callable[[int], None] | None = None,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY,
    save_to: str | Path | None = None,
    checkpoint_every_s: float = DEFAULT_CHECKPOINT_EVERY_S,
    cache: bool = False,
) -> ReachabilityMap:
    """Build a reachability map of one arm by random joint sampling.

    With ``checkpoint``, the build is resumable (see ``checkpoint.py``): the state is saved
    atomically to that file every ``checkpoint_every`` samples or ``checkpoint_every_s``
    seconds, whichever comes first, and on the first Ctrl-C; a build started with an existing
    checkpoint of the same robot, URDF, arm and settings resumes after its last finished chunk,
    and the map equals that of an uninterrupted build.

    With ``save_to``, the map is written there (atomically and durably: fsync, rename, fsync of
    the directory) before the checkpoint is removed, so a kill at any moment loses at most the
    work since the last checkpoint. The output is locked (:func:`baseplace.files.output_lock`)
    for the whole build: a second build to the same file waits, then reuses the map the first
    wrote if it is of the same build, and temporary files of a killed save are removed.

    Args:
        robot: the robot.
        arm_name: which arm (the robot's default arm if None).
        settings: build settings (defaults: 2e8 samples, 50 mm, 0.8 rad, seed 0, support test at 0.8).
        progress: called with the number of samples done after each chunk (on resuming, first
            with the samples the checkpoint holds).
        checkpoint: checkpoint file (by convention the map path + ``.partial``), or None.
        checkpoint_every: samples between checkpoints, rounded up to whole chunks of 2^20.
        save_to: map file to write, or None (the caller saves the returned map).
        checkpoint_every_s: build time [s] between checkpoints.
        cache: ``save_to`` and ``checkpoint`` are a cache entry: when they do not fit on the
            disk they are skipped with a one-line warning, and the map is still returned.

    Returns:
        The map; ``info.build_time_s`` sums the wall time of every run of a resumed build.

    Raises:
        InputError: the checkpoint is corrupt or from another build (delete it to start over),
            its directory does not exist, or ``checkpoint_every`` < 1.
        OutputError: the map or a checkpoint does not fit on the disk (not for a cache); the
            previous files are untouched.
        KeyboardInterrupt: Ctrl-C; with a checkpoint, it holds every chunk finished.
    """
    settings = settings or BuildSettings()
    acc = MapAccumulator(robot, arm_name, settings)
    target = save_to if save_to is not None else checkpoint
    if target is None:
        return _build(acc, progress, None, checkpoint_every, checkpoint_every_s)
    before = _stat(save_to)
    with output_lock(target):
        if save_to is not None and _stat(save_to) != before:  # written while we waited
            reused = _reuse(save_to, acc)
            if reused is not None:
                return reused
        for path in (save_to, checkpoint):
            if path is not None:
                remove_stray_temporaries(path)
        return _build(acc, progress, checkpoint, checkpoint_every, checkpoint_every_s, save_to, cache)


def _stat(path: str | Path | None) -> tuple[int, int] | None:
    try:
        st = os.stat(path) if path is not None else None
    except OSError:
        return None
    return None if st is None else (st.st_mtime_ns, st.st_ino)


def _reuse(path: str | Path, acc: MapAccumulator) -> ReachabilityMap | None:
    """The map at ``path`` if it is of exactly the build ``acc`` would do, else None."""
    try:
        rmap = load_map(path, acc.robot, acc.arm.name)
    except InputError:
        return None
    info, s = rmap.info, acc.settings
    same = (
        rmap.grid == acc.grid
        and (info.samples, info.seed, info.self_collision) == (s.samples, s.seed, s.self_collision)
        and bool(info.certification) == (s.certify > 0)
        and (not info.certification or json.loads(info.certification)["below"] == s.certify)
        and (rmap.manipulability is not None) == s.manipulability
        and (built_threshold(rmap.info) if rmap.info.supported else 0.0)
        == (s.support_threshold if support_count(rmap.counts, acc.arm.n_joints) else 0.0)
    )
    return rmap if same else None


def _build(
    acc: MapAccumulator,
    progress: Callable[[int], None] | None,
    checkpoint: str | Path | None,
    checkpoint_every: int,
    checkpoint_every_s: float,
    save_to: str | Path | None = None,
    cache: bool = False,
) -> ReachabilityMap:
    settings = acc.settings
    if checkpoint is None:
        start = time.perf_counter()
        for k in range(acc.n_chunks):
            acc.add_chunk(k)
            if progress is not None:
                progress(min(settings.samples, (k + 1) * CHUNK))
        rmap = acc.result(time.perf_counter() - start)
        if save_to is not None:
            save_map(rmap, save_to)
        return rmap

    with Checkpoints(acc, checkpoint, checkpoint_every, checkpoint_every_s, cache) as saver:
        if progress is not None and saver.resumed_chunks:
            progress(acc.samples_done)
        for k in acc.pending_chunks():
            acc.add_chunk(int(k))
            if progress is not None:
                progress(acc.samples_done)
            saver.added(1)
        return saver.finish(save_to)
