"""Saving and loading reachability maps as HDF5 (never pickle).

Layout: datasets ``cells`` (int64), ``counts`` (uint32) and optionally ``manipulability``
(float32); the JSON texts ``grid`` and ``info`` (the provenance, :class:`MapInfo`) as uint8 datasets
(see :mod:`baseplace.h5files`); attributes hold the format, its version and a SHA-256 of the
datasets. Writes go to a temporary file in the target directory and are renamed
into place, so a crash never leaves a half-written map under the final name.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
import numpy as np

from baseplace import h5files
from baseplace.errors import InputError
from baseplace.files import MAP_FILE, atomic_hdf5, existing_file
from baseplace.reachability.grid import SE3Grid
from baseplace.reachability.rmap import MapInfo, ReachabilityMap

if TYPE_CHECKING:
    from baseplace.robots.model import Robot

FORMAT = "baseplace-reachability-map"
FORMAT_VERSION = 2  # 1 kept grid and info in variable-length string attributes


def save_map(rmap: ReachabilityMap, path: str | Path, compress: bool = True) -> int:
    """Write ``rmap`` to ``path`` atomically; returns the file size in bytes.

    ``compress=False`` stores the arrays without gzip: about 11x the size, opened about 3x faster
    (the per-user cache keeps its maps so, :mod:`baseplace.reachability.cache`).
    """
    path = Path(path)
    packed = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if compress else {}
    gzip = {"compression": "gzip"} if compress else {}  # the optional arrays: gzip's default level
    with atomic_hdf5(path, "map") as f:
        h5files.write_header(f, FORMAT, FORMAT_VERSION)
        grid = rmap.grid
        grid_text = json.dumps(
            {
                "origin": list(grid.origin),
                "voxel_size": grid.voxel_size,
                "shape": list(grid.shape),
                "nside": grid.nside,
                "n_twist": grid.n_twist,
            }
        )
        parts: list[np.ndarray | bytes] = [
            h5files.write_text(f, "grid", grid_text),
            h5files.write_text(f, "info", json.dumps(dataclasses.asdict(rmap.info))),
            rmap.cells,
            rmap.counts,
        ]
        f.create_dataset("cells", data=rmap.cells, **packed)
        f.create_dataset("counts", data=rmap.counts, **packed)
        if rmap.manipulability is not None:
            f.create_dataset("manipulability", data=rmap.manipulability, **gzip)
            parts.append(rmap.manipulability)
        if rmap.quality is not None:
            f.create_dataset("quality", data=rmap.quality, **gzip)
            parts.append(rmap.quality)
        f.attrs["sha256"] = h5files.short_text(h5files.digest(*parts))
    return path.stat().st_size


def is_compressed(path: str | Path) -> bool:
    """Whether the map file's cells are stored compressed (False for an unreadable file)."""
    try:
        with h5py.File(path, "r") as f:
            if not isinstance(f.get("cells", getlink=True), h5py.HardLink):
                return False  # absent, or a link that load_map refuses: never followed here
            cells = f["cells"]
            return isinstance(cells, h5py.Dataset) and cells.compression is not None
    except h5files.CORRUPT_FILE_ERRORS:
        return False


def load_map(path: str | Path, robot: Robot | None = None, arm: str | None = None) -> ReachabilityMap:
    """Read a map; with ``robot``, check it was built for that robot's URDF (and ``arm``).

    Raises:
        InputError: missing, truncated or corrupt file, a newer format version, or a map of
            another robot, URDF or arm.
    """
    path = existing_file(path, MAP_FILE)
    try:
        with h5py.File(path, "r") as f:
            h5files.read_header(
                f, path, FORMAT, FORMAT_VERSION, "reachability map", "rebuild it with build-map"
            )
            grid_text, info_text = h5files.read_text(f, "grid"), h5files.read_text(f, "info")
            g = _grid(json.loads(grid_text), path)  # the grid's size is checked before the arrays are read
            cells = h5files.read_array(f, "cells", path)
            counts = h5files.read_array(f, "counts", path)
            manip = h5files.read_array(f, "manipulability", path) if "manipulability" in f else None
            quality = h5files.read_array(f, "quality", path) if "quality" in f else None
            stored = h5files.attr_text(f.attrs, "sha256")
        arrays: list[np.ndarray] = [cells, counts] + [a for a in (manip, quality) if a is not None]
        if h5files.digest(grid_text, info_text, *arrays) != stored:
            raise InputError(f"cannot read map {path}: checksum mismatch, the file is corrupt")
        info_raw = json.loads(info_text)
        info_raw["joint_names"] = tuple(info_raw["joint_names"])
        try:
            info = MapInfo(**info_raw)
        except InputError as exc:  # a value out of range (the support test's): name the file
            raise InputError(f"cannot read map {path}: {exc}") from None
        grid = g
        if (
            cells.ndim != 1
            or cells.shape != counts.shape
            or (manip is not None and manip.shape != cells.shape)
            or (quality is not None and (quality.shape != cells.shape or quality.dtype != np.float32))
            or (len(cells) and not 0 <= cells.min() <= cells.max() < grid.n_cells)
        ):
            raise ValueError("cells out of the grid")
        # copy=False: stored as these types (the usual case), the arrays just read are used as they are
        rmap = ReachabilityMap(
            grid,
            cells.astype(np.int64, copy=False),
            counts.astype(np.uint32, copy=False),
            info,
            manip,
            quality,
        )
    except InputError:
        raise
    except h5files.CORRUPT_FILE_ERRORS as exc:
        raise InputError(
            f"cannot read map {path}: the file is truncated or corrupt ({type(exc).__name__})"
        ) from None
    if robot is not None:
        check_map_matches(rmap, robot, arm, path)
    return rmap


MAX_NSIDE = 64
MAX_TWIST = 4096
MAX_CELLS = 2**40
MAX_VOXELS = 2**27
"""Voxels of a map's grid: a query allocates 4 bytes per voxel (``ReachabilityMap.tables``).

2^27 (512 MB of table) is 3 m x 3 m x 2 m at 7 mm voxels, far beyond any arm's build."""


def _grid(g: dict[str, object], source: Path) -> SE3Grid:
    """The grid of a map file, with its sizes bounded before anything is allocated."""
    nside, n_twist = int(g["nside"]), int(g["n_twist"])  # type: ignore[call-overload]
    shape = tuple(int(v) for v in g["shape"])  # type: ignore[attr-defined]
    if not (1 <= nside <= MAX_NSIDE and 1 <= n_twist <= MAX_TWIST and len(shape) == 3 and min(shape) >= 1):
        raise ValueError("grid sizes out of range")
    n_voxels = float(np.prod(shape, dtype=float))
    if n_voxels * 12 * nside * nside * n_twist > MAX_CELLS or n_voxels > MAX_VOXELS:
        raise InputError(
            f"cannot read map {source}: its grid of {shape[0]} x {shape[1]} x {shape[2]} voxels and {12 * nside * nside * n_twist} "
            f"orientations is beyond the limits ({MAX_VOXELS} voxels, {MAX_CELLS} cells); the file is corrupt"
        )
    origin = tuple(float(v) for v in g["origin"])  # type: ignore[attr-defined]
    if not all(isinstance(v, (int, float)) for v in (g["voxel_size"], *g["origin"])):  # type: ignore[misc]
        raise TypeError("grid numbers must be numbers")
    voxel_size = float(g["voxel_size"])  # type: ignore[arg-type]
    if len(origin) != 3 or not (np.isfinite(origin).all() and math.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError("grid origin or voxel size out of range")
    return SE3Grid(origin, voxel_size, shape, nside, n_twist)


def check_map_matches(
    rmap: ReachabilityMap, robot: Robot, arm: str | None, source: Path | str = "map"
) -> None:
    """Raise unless ``rmap`` was built for ``robot`` (same name and URDF) and ``arm``."""
    info = rmap.info
    if info.robot != robot.name:
        raise InputError(
            f"{source} was built for robot {info.robot!r}, not {robot.name!r}; rebuild it with build-map"
        )
    if info.urdf_sha256 != robot.spec.urdf_sha256:
        raise InputError(
            f"{source} was built from a different URDF of {robot.name!r} "
            f"(sha256 {info.urdf_sha256[:12]} != {robot.spec.urdf_sha256[:12]}); rebuild it"
        )
    expected = robot.spec.default_arm if arm is None else arm
    if info.arm != expected:
        raise InputError(f"{source} is for arm {info.arm!r}, not {expected!r}")
