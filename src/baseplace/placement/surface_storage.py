"""Saving and loading surface maps as sparse HDF5 (seed 002 V-A keeps only poses with R_S > 0).

Layout: ``index`` (uint32 flat indices into the (T, NX, NY) grid of the poses with R_S > 0) and
``value`` (their R_S as uint16, R_S * 65535 rounded: 1.5e-5 resolution); attributes hold the
grid, the surface, the robot and arms, the format version and a SHA-256 of the datasets. Loading
rebuilds the dense grid, so lookups stay constant-time. Writes are atomic.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import h5py
import numpy as np

from baseplace.errors import InputError
from baseplace.files import atomic_write
from baseplace.placement.surface_map import SurfaceMap

FORMAT = "baseplace-surface-map"
FORMAT_VERSION = 1
SCALE = 65535
MAX_POSES = 10**9


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def save_surface_map(smap: SurfaceMap, path: str | Path) -> int:
    """Write ``smap`` to ``path`` atomically, keeping only poses with R_S > 0; returns the size [bytes]."""
    path = Path(path)
    index = np.flatnonzero(smap.values).astype(np.uint32)
    value = np.maximum(1, np.rint(smap.values.ravel()[index] * SCALE)).astype(np.uint16)
    meta = {
        "shape": list(smap.values.shape), "origin": list(smap.origin), "resolution": smap.resolution,
        "polygon": smap.polygon.tolist(), "height": smap.height, "robot": smap.robot, "arms": list(smap.arms),
        "combine": smap.combine, "cone": smap.cone, "tcp_height": smap.tcp_height,
    }  # fmt: skip
    with atomic_write(path, "surface map") as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["meta"] = json.dumps(meta)
        f.create_dataset("index", data=index, compression="gzip", shuffle=True)
        f.create_dataset("value", data=value, compression="gzip", shuffle=True)
        f.attrs["sha256"] = _digest(index, value)
    return path.stat().st_size


def load_surface_map(path: str | Path) -> SurfaceMap:
    """Read a surface map written by :func:`save_surface_map`.

    Raises:
        InputError: missing, truncated or corrupt file, another kind of file, or a newer format.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"surface map {path} does not exist")
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise InputError(f"{path} is not a baseplace surface map (make one with surface-map)")
            version = int(f.attrs["format_version"])
            if version > FORMAT_VERSION:
                raise InputError(f"{path} has surface map format {version}, newer than this baseplace reads")
            meta = json.loads(f.attrs["meta"])
            index, value = f["index"][()], f["value"][()]
            digest = str(f.attrs["sha256"])
        if _digest(index, value) != digest:
            raise InputError(f"cannot read surface map {path}: checksum mismatch, the file is corrupt")
        shape = tuple(int(v) for v in meta["shape"])
        if len(shape) != 3 or min(shape) < 1 or float(np.prod(shape, dtype=float)) > MAX_POSES:
            raise ValueError("grid shape out of range")
        values = np.zeros(int(np.prod(shape)), dtype=np.float32)
        values[index] = value.astype(np.float32) / SCALE
        smap = SurfaceMap(
            values.reshape(shape), (float(meta["origin"][0]), float(meta["origin"][1])), float(meta["resolution"]),
            np.asarray(meta["polygon"], dtype=float), float(meta["height"]), str(meta["robot"]), tuple(meta["arms"]),
            str(meta["combine"]), None if meta["cone"] is None else float(meta["cone"]), float(meta["tcp_height"]),
        )  # fmt: skip
    except InputError:
        raise
    except (
        OSError,
        KeyError,
        ValueError,
        TypeError,
        IndexError,
        AttributeError,
        RecursionError,
        MemoryError,
    ) as exc:
        raise InputError(
            f"cannot read surface map {path}: truncated or corrupt ({type(exc).__name__})"
        ) from None
    return smap
