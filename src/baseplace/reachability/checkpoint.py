"""Resumable map builds: the state of a build saved atomically to an HDF5 checkpoint (never pickle).

A checkpoint is the :class:`~baseplace.reachability.build.PartialMap` of the chunks finished so
far (their indices, the sparse counts, the best manipulability, the self-collision drops) plus
what identifies the build: robot name, URDF SHA-256, arm, every build setting, the chunk size and
the grid. Since chunk ``k`` is drawn from ``default_rng([seed, k])`` whatever ran before it, a
build resumed from a checkpoint gives exactly the map an uninterrupted build gives.

Layout: datasets ``chunks`` (int64), ``cells`` (int64), ``counts`` (uint32) and, with
manipulability, ``best`` (float32), and the text ``build`` (JSON of the identity) as a uint8 dataset
(see :mod:`baseplace.h5files`); attributes ``format``, ``format_version``, ``dropped``,
``elapsed_s`` (build wall time so far) and ``sha256`` over all of it.
Writes go through :func:`baseplace.files.atomic_hdf5` (built in memory, then a temporary file
renamed), so a build killed at any moment, even with SIGKILL while writing, leaves either the
previous checkpoint or the new one, never a torn file; a full disk leaves the previous one too. The convention for a map written to ``OUT`` is the checkpoint ``OUT.partial``
(:func:`default_checkpoint_path`).

Ctrl-C: while a checkpointed build runs in the main thread, the first SIGINT is deferred to the
end of the chunk (or task) in progress, a final checkpoint is written and ``KeyboardInterrupt``
is raised; a second SIGINT stops at once and leaves the last periodic checkpoint, which is
valid.
"""

from __future__ import annotations

import dataclasses
import json
import math
import signal
import threading
import time
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

import h5py
import numpy as np

from baseplace import h5files
from baseplace.errors import InputError
from baseplace.files import OutputError, atomic_hdf5, skip_cache_entry
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.sampling import CHUNK, MapAccumulator, PartialMap

FORMAT = "baseplace-build-checkpoint"
FORMAT_VERSION = 2  # 1 kept build in a variable-length string attribute
SUFFIX = ".partial"


def default_checkpoint_path(map_path: str | Path) -> Path:
    """The checkpoint of a build whose map goes to ``map_path``: ``map_path`` + ``.partial``."""
    path = Path(map_path)
    return path.with_name(path.name + SUFFIX)


def build_identity(acc: MapAccumulator) -> dict[str, Any]:
    """What a checkpoint must match to be resumed by ``acc``'s build (JSON-ready)."""
    g = acc.grid
    identity = {
        "robot": acc.robot.name,
        "urdf_sha256": acc.robot.spec.urdf_sha256,
        "arm": acc.arm.name,
        "settings": dataclasses.asdict(acc.settings),
        "chunk": CHUNK,
        "grid": {
            "origin": list(g.origin),
            "voxel_size": g.voxel_size,
            "shape": list(g.shape),
            "nside": g.nside,
            "n_twist": g.n_twist,
        },
    }
    return json.loads(json.dumps(identity))  # the form it takes after a round trip through the file


def _digest(build: bytes, dropped: int, elapsed_s: float, arrays: list[np.ndarray]) -> str:
    return h5files.digest(build + f"\n{dropped}\n{elapsed_s!r}\n".encode(), *arrays)


def save_checkpoint(path: str | Path, acc: MapAccumulator, elapsed_s: float) -> None:
    """Write the state of ``acc`` (every chunk added so far) to ``path`` atomically.

    Args:
        path: checkpoint file; replaced if it exists.
        acc: the build's accumulator.
        elapsed_s: build wall time so far [s], summed over resumed runs.

    Raises:
        InputError: the directory of ``path`` does not exist.
        OutputError: the disk cannot hold it; the previous checkpoint is untouched.
    """
    part = acc.partial()
    build = json.dumps(build_identity(acc), sort_keys=True)
    arrays: list[np.ndarray] = [part.chunks, part.cells, part.counts]
    if part.best is not None:
        arrays.append(part.best)
    with atomic_hdf5(path, "checkpoint") as f:
        h5files.write_header(f, FORMAT, FORMAT_VERSION)
        build_text = h5files.write_text(f, "build", build)
        f.attrs["dropped"] = part.dropped
        f.attrs["elapsed_s"] = elapsed_s
        for name, a in zip(("chunks", "cells", "counts", "best"), arrays, strict=False):
            f.create_dataset(name, data=a)
        f.attrs["sha256"] = h5files.short_text(_digest(build_text, part.dropped, elapsed_s, arrays))


def _mismatch(stored: dict[str, Any], current: dict[str, Any]) -> str | None:
    """The first field that differs, as "name stored, now current", or None."""
    for key in ("robot", "urdf_sha256", "arm", "settings", "chunk", "grid"):
        a, b = stored.get(key), current[key]
        if key == "settings" and isinstance(a, dict):
            for name, value in b.items():
                if a.get(name) != value:
                    return f"{name} {a.get(name)!r}, now {value!r}"
        elif a != b:
            if key == "urdf_sha256" and isinstance(a, str):
                return f"URDF sha256 {a[:12]}, now {b[:12]}"
            return f"{key} {a!r}, now {b!r}"
    return None


def load_checkpoint(path: str | Path, acc: MapAccumulator) -> float:
    """Merge the checkpoint at ``path`` into a fresh ``acc``; returns the build time so far [s].

    Raises:
        InputError: the file is missing, truncated or corrupt, of a newer format, or from
            another build (robot, URDF, arm or any setting differs); the message says to delete it.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"checkpoint {path} does not exist")
    corrupt = (
        f"cannot resume from checkpoint {path}: the file is truncated or corrupt; delete it to start over"
    )
    try:
        with h5py.File(path, "r") as f:
            h5files.read_header(
                f, path, FORMAT, FORMAT_VERSION, "build checkpoint", "delete it to start over"
            )
            build = h5files.read_text(f, "build")
            dropped = int(f.attrs["dropped"])
            elapsed_s = float(f.attrs["elapsed_s"])
            arrays = [
                h5files.read_array(f, name, path)
                for name in ("chunks", "cells", "counts", "best")
                if name in f
            ]
            stored = h5files.attr_text(f.attrs, "sha256")
        if _digest(build, dropped, elapsed_s, arrays) != stored or len(arrays) < 3:
            raise InputError(corrupt)
        identity = json.loads(build)
    except InputError:
        raise
    except h5files.CORRUPT_FILE_ERRORS:
        raise InputError(corrupt) from None
    difference = _mismatch(identity, build_identity(acc))
    if difference is not None:
        raise InputError(
            f"checkpoint {path} is from another build ({difference}); delete it to start over, "
            "or rerun with the settings it was written with"
        )
    chunks, cells, counts = (
        a.astype(t) for a, t in zip(arrays, (np.int64, np.int64, np.uint32), strict=False)
    )
    best = arrays[3].astype(np.float32) if len(arrays) > 3 else None
    samples = acc.settings.samples
    in_chunks = int(np.minimum(CHUNK, samples - chunks * CHUNK).sum()) if len(chunks) else 0
    if int(counts.sum(dtype=np.int64)) + dropped != in_chunks:
        raise InputError(corrupt)
    try:
        acc.merge(PartialMap(chunks, cells, counts, best, dropped))
    except InputError as exc:
        raise InputError(f"cannot resume from checkpoint {path}: {exc}; delete it to start over") from None
    return elapsed_s


def remove_checkpoint(path: str | Path) -> None:
    """Delete a checkpoint and any temporary file a killed write left beside it."""
    path = Path(path)
    path.unlink(missing_ok=True)
    directory = path.parent if str(path.parent) else Path(".")
    for stray in directory.glob(f".{path.name}.*.tmp"):  # atomic_write's temporary names
        stray.unlink(missing_ok=True)


class _DeferredInterrupt:
    """Turns the first SIGINT into a flag (checked between chunks); the second interrupts at once."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        self._installed = False

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def install(self) -> None:
        # Only the main thread receives signals, and a handler someone else installed (or SIGINT
        # ignored, as for background jobs) is left alone.
        if threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return
        self._previous = signal.signal(signal.SIGINT, self._handle)
        self._installed = True

    def uninstall(self) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous)
            self._installed = False


class Checkpoints:
    """Periodic checkpoints of one build: resumes on creation, saves as chunks finish.

    Use as a context manager around the build loop; call :meth:`added` after each chunk or task
    is merged into the accumulator, and :meth:`finish` for the map (which removes the file).
    An exception leaves the last checkpoint on disk for the next run to resume from.

    Args:
        acc: the build's accumulator, with nothing added yet.
        path: the checkpoint file; if it exists, the build resumes from it.
        every: samples between checkpoints, rounded to whole chunks (at least one chunk).
        every_s: build time [s] between checkpoints (whichever of the two comes first), so a
            kill loses at most about this much work.
        cache: the build of a cache entry: a checkpoint or a map that does not fit on the disk is
            skipped with a one-line warning (:class:`~baseplace.files.CacheSkipped`) and the
            build goes on; otherwise it raises :class:`~baseplace.files.OutputError`.

    Raises:
        InputError: ``every`` < 1 or ``every_s`` <= 0, the directory of ``path`` does not exist,
            or the existing checkpoint is corrupt or from another build.
    """

    def __init__(
        self, acc: MapAccumulator, path: str | Path, every: int, every_s: float = 30.0, cache: bool = False
    ) -> None:
        if every < 1:
            raise InputError(f"checkpoint interval must be at least 1 sample, got {every}")
        if not every_s > 0:
            raise InputError(f"checkpoint interval must be more than 0 s, got {every_s}")
        self.every_s = every_s
        self.cache = cache
        self._full = False  # a cache's disk was full: no more checkpoints
        self.acc = acc
        self.path = Path(path)
        directory = self.path.parent if str(self.path.parent) else Path(".")
        if not directory.is_dir():
            raise InputError(f"cannot write checkpoint {self.path}: directory {directory} does not exist")
        self.every_chunks = max(1, math.ceil(every / CHUNK))
        self.resumed_chunks = 0
        self._previous_s = 0.0
        if self.path.exists():
            self._previous_s = load_checkpoint(self.path, acc)
            self.resumed_chunks = int(acc.done.sum())
        self._since = 0
        self._start = time.perf_counter()
        self._last_save = self._start
        self._interrupt = _DeferredInterrupt()

    def __enter__(self) -> Checkpoints:
        self._interrupt.install()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._interrupt.uninstall()

    @property
    def elapsed_s(self) -> float:
        """Build wall time [s], including the runs this one resumed."""
        return self._previous_s + time.perf_counter() - self._start

    def save(self) -> None:
        """Write the checkpoint now (a cache's, unless its disk was found full).

        Raises:
            OutputError: the checkpoint does not fit (not for a cache); the previous one is kept.
        """
        if not self._full:
            try:
                save_checkpoint(self.path, self.acc, self.elapsed_s)
            except OutputError as exc:
                if not self.cache:
                    raise
                self._full = True
                skip_cache_entry("the build's checkpoint", self.path.parent, exc)
        self._since = 0
        self._last_save = time.perf_counter()

    def check_interrupt(self) -> None:
        """After a deferred Ctrl-C: write a final checkpoint and raise ``KeyboardInterrupt``."""
        if self._interrupt.requested:
            self.save()
            raise KeyboardInterrupt

    def added(self, n_chunks: int = 1) -> None:
        """Note ``n_chunks`` more chunks merged; save if the interval is due or Ctrl-C was pressed."""
        self._since += n_chunks
        self.check_interrupt()
        due = self._since >= self.every_chunks or time.perf_counter() - self._last_save >= self.every_s
        if due and not self.acc.done.all():
            self.save()

    def finish(self, save_to: str | Path | None = None) -> ReachabilityMap:
        """The finished map, written to ``save_to`` first if given; then the checkpoint is removed.

        The checkpoint goes only once the map is durably on disk (``save_map`` fsyncs and renames
        atomically): a kill during the save leaves the checkpoint, and the next run resumes from it
        (with nothing left to sample) and saves again. Call it inside the ``with`` block: a first
        Ctrl-C during the save lets the save finish (the build is done); a second aborts it,
        leaving no temporary file and the checkpoint.
        """
        rmap = self.acc.result(self.elapsed_s)
        if save_to is not None:
            from baseplace.reachability.storage import save_map

            if time.perf_counter() - self._last_save > self.every_s / 2:
                self.save()  # so a kill during the map's save loses at most half an interval

            try:
                save_map(rmap, save_to)
            except OutputError as exc:
                if not self.cache:
                    raise  # the checkpoint stays: free some space and rerun to save the map
                skip_cache_entry("the map", Path(save_to).parent, exc)
                return rmap
        remove_checkpoint(self.path)
        return rmap
