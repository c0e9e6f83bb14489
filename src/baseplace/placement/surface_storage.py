"""Saving and loading surface maps as sparse HDF5 (seed 002 V-A keeps only poses with R_S > 0).

Layout: ``index`` (uint32 flat indices into the (T, NX, NY) grid of the poses with R_S > 0) and
``value`` (their R_S as uint16, R_S * 65535 rounded: 1.5e-5 resolution); the JSON text ``meta``
(grid, surface, robot and arms) as a uint8 dataset (see :mod:`baseplace.h5files`); attributes hold
the format, its version and a SHA-256 of the datasets. Loading
rebuilds the dense grid, so lookups stay constant-time. Writes are atomic.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np

from baseplace import h5files
from baseplace.errors import InputError
from baseplace.files import SURFACE_MAP_FILE, atomic_hdf5, existing_file
from baseplace.guards import check_alloc
from baseplace.placement.surface_map import SurfaceMap, parse_polygon

FORMAT = "baseplace-surface-map"
FORMAT_VERSION = 2  # 1 kept meta in a variable-length string attribute
SCALE = 65535
MAX_POSES = 10**9
MAX_HEIGHT = 100.0  # m: heights, TCP heights (and the cone, in rad) beyond this are corrupt
MAX_POLYGON_VERTICES = 10_000


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
    with atomic_hdf5(path, "surface map") as f:
        h5files.write_header(f, FORMAT, FORMAT_VERSION)
        meta_text = h5files.write_text(f, "meta", json.dumps(meta))
        f.create_dataset("index", data=index, compression="gzip", shuffle=True)
        f.create_dataset("value", data=value, compression="gzip", shuffle=True)
        f.attrs["sha256"] = h5files.short_text(h5files.digest(meta_text, index, value))
    return path.stat().st_size


def load_surface_map(path: str | Path) -> SurfaceMap:
    """Read a surface map written by :func:`save_surface_map`.

    Raises:
        InputError: missing, truncated or corrupt file, another kind of file, or a newer format.
    """
    path = existing_file(path, SURFACE_MAP_FILE)
    try:
        with h5py.File(path, "r") as f:
            h5files.read_header(f, path, FORMAT, FORMAT_VERSION, "surface map", "rebuild it with surface-map")
            meta_text = h5files.read_text(f, "meta")
            index, value = h5files.read_array(f, "index", path), h5files.read_array(f, "value", path)
            stored = h5files.attr_text(f.attrs, "sha256")
        if h5files.digest(meta_text, index, value) != stored:
            raise InputError(f"cannot read surface map {path}: checksum mismatch, the file is corrupt")
        meta = json.loads(meta_text)
        shape = tuple(int(v) for v in meta["shape"])
        if len(shape) != 3 or min(shape) < 1 or float(np.prod(shape, dtype=float)) > MAX_POSES:
            raise ValueError("grid shape out of range")
        check_alloc(float(np.prod(shape, dtype=float)) * 4, "the surface map's grid", path)
        if (
            index.ndim != 1
            or index.shape != value.shape
            or (len(index) and not 0 <= index.min() <= index.max() < np.prod(shape))
        ):
            raise ValueError("index out of the grid")
        values = np.zeros(int(np.prod(shape)), dtype=np.float32)
        values[index] = value.astype(np.float32) / SCALE
        numbers = [float(meta["height"]), float(meta["tcp_height"])] + (
            [] if meta["cone"] is None else [float(meta["cone"])]
        )
        if not all(math.isfinite(v) and abs(v) <= MAX_HEIGHT for v in numbers):
            raise InputError(
                f"cannot read surface map {path}: height, TCP height or cone is not finite or beyond {MAX_HEIGHT:g}"
            )
        if not isinstance(meta["polygon"], list) or len(meta["polygon"]) > MAX_POLYGON_VERTICES:
            raise ValueError("polygon too long")
        origin, resolution = [float(v) for v in meta["origin"]], float(meta["resolution"])
        if len(origin) != 2 or not (
            np.isfinite(origin).all() and math.isfinite(resolution) and resolution > 0
        ):
            raise ValueError("grid origin or resolution out of range")
        try:
            polygon = parse_polygon(meta["polygon"])
        except InputError:
            raise ValueError("not a polygon") from None
        smap = SurfaceMap(
            values.reshape(shape), (origin[0], origin[1]), resolution, polygon, float(meta["height"]),
            str(meta["robot"]), tuple(meta["arms"]), str(meta["combine"]),
            None if meta["cone"] is None else float(meta["cone"]), float(meta["tcp_height"]),
        )  # fmt: skip
    except InputError:
        raise
    except h5files.CORRUPT_FILE_ERRORS as exc:
        raise InputError(
            f"cannot read surface map {path}: truncated or corrupt ({type(exc).__name__})"
        ) from None
    return smap
