"""Arrays derived from a robot's geometry, kept on disk between processes.

The state pre-filter's anchor fields, self-pair distance tables and sphere covers
(:mod:`~baseplace.world.state_filter`) take about 2 s to compute for TIAGo and depend only on the
robot's collision geometry: a one-shot ``baseplace place`` would pay that on every run. :func:`cached_array` keeps such an array under the per-user cache
(:func:`~baseplace.files.cache_root`, ``fields/``) in NumPy's ``.npy`` format, named by a hash of
everything it was computed from (its inputs, and the source file of the function that computes it:
an edit of that code computes the array again), and reads it back only after checking, before anything is
allocated, that the file holds exactly the array expected (its header's dtype and shape, its
size); any other file is ignored and the array computed again. Never a pickle.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.files import OutputError, cache_root, private_dir, skip_cache_entry

VERSION = b"baseplace-array-cache-1"
"""Part of every key: a change of what an array means changes this."""
HEADER_MAX = 4096
"""Bytes an ``.npy`` header may take (NumPy's are 64-128)."""


def cached_array(
    name: str,
    inputs: Sequence[NDArray[np.generic] | float | int | str | bytes],
    shape: tuple[int, ...],
    dtype: np.dtype[np.generic] | type,
    compute: Callable[[], NDArray[np.generic]],
) -> NDArray[np.generic]:
    """The array ``compute()`` returns (``shape``, ``dtype``), read from the cache when it holds it.

    Args:
        name: what the array is (a file name part: letters, digits, ``_``).
        inputs: everything the array is computed from; their bytes, dtypes and shapes make the key.
        shape: the array's shape.
        dtype: its dtype (stored little-endian).
        compute: makes the array when the cache does not hold it (a function, or a
            :func:`functools.partial` of one, defined in a source file: its bytes are in the key).
    """
    dt = np.dtype(dtype).newbyteorder("<")
    path = _directory() / f"{name}-{_key(name, (*inputs, _source(compute)), shape, dt)}.npy"
    kept = _read(path, shape, dt)
    if kept is not None:
        return kept
    value = np.ascontiguousarray(compute(), dtype=dt)
    if value.shape != tuple(shape):
        raise ValueError(f"{name}: computed shape {value.shape}, expected {tuple(shape)}")
    _write(path, value)
    return value


def _directory() -> Path:
    return cache_root() / "fields"


def _source(compute: Callable[[], NDArray[np.generic]]) -> bytes:
    """The bytes of the source file that defines ``compute`` (through a :func:`functools.partial`)."""
    func = compute.func if isinstance(compute, functools.partial) else compute
    path = inspect.getsourcefile(func)
    if path is None:
        raise ValueError(f"{func!r} has no source file to key the cache by")
    return Path(path).read_bytes()


def _key(
    name: str,
    inputs: Sequence[NDArray[np.generic] | float | int | str | bytes],
    shape: tuple[int, ...],
    dt: np.dtype[np.generic],
) -> str:
    h = hashlib.sha256(VERSION)
    h.update(repr((name, tuple(int(n) for n in shape), dt.str)).encode())
    for x in inputs:
        a = np.ascontiguousarray(x)
        h.update(repr((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:40]


def _read(path: Path, shape: tuple[int, ...], dt: np.dtype[np.generic]) -> NDArray[np.generic] | None:
    """The array in ``path`` if it is exactly ``shape`` of ``dt`` (checked before reading its data), else None."""
    count = int(np.prod(shape, dtype=np.int64))
    try:
        size = path.stat().st_size
        if not count * dt.itemsize < size <= count * dt.itemsize + HEADER_MAX:
            return None
        with path.open("rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                header = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                header = np.lib.format.read_array_header_2_0(f)
            else:
                return None
            if header != (tuple(shape), False, dt):
                return None
            data = np.fromfile(f, dtype=dt, count=count)
    except Exception:  # a garbled header makes NumPy's parser raise ValueError,
        return None  # SyntaxError, tokenize's TokenError...: any such file is not the array
    return data.reshape(shape) if data.size == count else None


def _write(path: Path, value: NDArray[np.generic]) -> None:
    """Store ``value`` at ``path`` atomically (a temporary file renamed); a failure costs the next run the work."""
    tmp = None
    try:
        directory = private_dir(path.parent)
        fd, tmp = tempfile.mkstemp(dir=directory, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.lib.format.write_array(f, value, allow_pickle=False)
        os.replace(tmp, path)
        tmp = None
    except (OSError, InputError, OutputError) as exc:
        skip_cache_entry(f"array {path.name}", path.parent, exc)
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
