"""Saving and loading reachability maps as HDF5 (never pickle).

Layout: datasets ``cells`` (int64), ``counts`` (uint32) and optionally ``manipulability``
(float32); attributes hold the grid, the provenance (:class:`MapInfo`), the format version and a
SHA-256 of the datasets. Writes go to a temporary file in the target directory and are renamed
into place, so a crash never leaves a half-written map under the final name.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import h5py
import numpy as np

from baseplace.errors import InputError
from baseplace.files import atomic_write
from baseplace.reachability.grid import SE3Grid
from baseplace.reachability.rmap import MapInfo, ReachabilityMap
from baseplace.robots.model import Robot

FORMAT = "baseplace-reachability-map"
FORMAT_VERSION = 1


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def save_map(rmap: ReachabilityMap, path: str | Path) -> int:
    """Write ``rmap`` to ``path`` atomically; returns the file size in bytes."""
    path = Path(path)
    with atomic_write(path, "map") as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        grid = rmap.grid
        f.attrs["grid"] = json.dumps(
            {
                "origin": list(grid.origin),
                "voxel_size": grid.voxel_size,
                "shape": list(grid.shape),
                "nside": grid.nside,
                "n_twist": grid.n_twist,
            }
        )
        f.attrs["info"] = json.dumps(dataclasses.asdict(rmap.info))
        f.create_dataset("cells", data=rmap.cells, compression="gzip", compression_opts=4, shuffle=True)
        f.create_dataset("counts", data=rmap.counts, compression="gzip", compression_opts=4, shuffle=True)
        arrays: list[np.ndarray] = [rmap.cells, rmap.counts]
        if rmap.manipulability is not None:
            f.create_dataset("manipulability", data=rmap.manipulability, compression="gzip")
            arrays.append(rmap.manipulability)
        f.attrs["sha256"] = _digest(*arrays)
    return path.stat().st_size


def load_map(path: str | Path, robot: Robot | None = None, arm: str | None = None) -> ReachabilityMap:
    """Read a map; with ``robot``, check it was built for that robot's URDF (and ``arm``).

    Raises:
        InputError: missing, truncated or corrupt file, a newer format version, or a map of
            another robot, URDF or arm.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"map file {path} does not exist")
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise InputError(f"{path} is not a baseplace reachability map")
            version = int(f.attrs["format_version"])
            if version > FORMAT_VERSION:
                raise InputError(
                    f"{path} has map format version {version}, newer than this baseplace reads "
                    f"({FORMAT_VERSION}); upgrade baseplace"
                )
            g = json.loads(f.attrs["grid"])
            info_raw = json.loads(f.attrs["info"])
            cells = f["cells"][()]
            counts = f["counts"][()]
            manip = f["manipulability"][()] if "manipulability" in f else None
            digest = str(f.attrs["sha256"])
        arrays: list[np.ndarray] = [cells, counts] + ([manip] if manip is not None else [])
        if _digest(*arrays) != digest:
            raise InputError(f"cannot read map {path}: checksum mismatch, the file is corrupt")
        info_raw["joint_names"] = tuple(info_raw["joint_names"])
        info = MapInfo(**info_raw)
        grid = _grid(g)
        if (
            cells.ndim != 1
            or cells.shape != counts.shape
            or (len(cells) and not 0 <= cells.min() <= cells.max() < grid.n_cells)
        ):
            raise ValueError("cells out of the grid")
        rmap = ReachabilityMap(grid, cells.astype(np.int64), counts.astype(np.uint32), info, manip)
    except InputError:
        raise
    except (OSError, KeyError, ValueError, TypeError, AttributeError, RecursionError, MemoryError) as exc:
        raise InputError(
            f"cannot read map {path}: the file is truncated or corrupt ({type(exc).__name__})"
        ) from None
    if robot is not None:
        check_map_matches(rmap, robot, arm, path)
    return rmap


MAX_NSIDE = 64
MAX_TWIST = 4096
MAX_CELLS = 2**40


def _grid(g: dict[str, object]) -> SE3Grid:
    """The grid of a map file, with its sizes bounded before anything is allocated."""
    nside, n_twist = int(g["nside"]), int(g["n_twist"])  # type: ignore[call-overload]
    shape = tuple(int(v) for v in g["shape"])  # type: ignore[attr-defined]
    if not (1 <= nside <= MAX_NSIDE and 1 <= n_twist <= MAX_TWIST and len(shape) == 3 and min(shape) >= 1):
        raise ValueError("grid sizes out of range")
    if float(np.prod(shape, dtype=float)) * 12 * nside * nside * n_twist > MAX_CELLS:
        raise ValueError("grid too large")
    origin = tuple(float(v) for v in g["origin"])  # type: ignore[attr-defined]
    if not all(isinstance(v, (int, float)) for v in (g["voxel_size"], *g["origin"])):  # type: ignore[misc]
        raise TypeError("grid numbers must be numbers")
    return SE3Grid(origin, float(g["voxel_size"]), shape, nside, n_twist)  # type: ignore[arg-type]


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
