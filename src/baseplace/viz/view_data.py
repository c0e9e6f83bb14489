"""The viewer's view data: a segmented scene and its OSRM heat map in one ``.npz`` beside a result.

The demo's result names such a file (key ``"view_data"``, relative to the JSON's directory or
absolute); :func:`view_data_from` makes it from a segmentation, :func:`save_view_data` writes it,
:func:`load_view_data` reads it back (no pickles). :func:`cell_quads` and :func:`height_at` turn it
into the meshes and ground heights the 3D scene (:mod:`baseplace.viz.view_scene`) draws.
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.files import atomic_write

if TYPE_CHECKING:
    from baseplace.placement.osrm import OSRM
    from baseplace.terrain.pipeline import Terrain

VIEW_DATA_VERSION = 1
MAX_POINTS = 200_000
"""Clouds are subsampled to at most this many points for the browser."""
MAX_CELLS = 400_000
"""Region and heat-map meshes are drawn on a coarser grid when they would have more cells."""

_KEYS = ("version", "robot", "points", "origin", "resolution", "labels", "heights", "planes", "osrm")


@dataclass(frozen=True)
class ViewData:
    """What the viewer needs besides the result JSON.

    Attributes:
        robot: robot name or robot-file path, as :class:`baseplace.robots.model.Robot` takes it.
        points: (N, 3) float32 cloud [m], subsampled to at most :data:`MAX_POINTS`.
        origin: (x, y) of the lower-left corner of height-map cell (0, 0) [m].
        resolution: height-map cell edge [m].
        labels: (H, W) int16 region id per cell (rows along y), -1 where none.
        heights: (H, W) float32 surface height per cell [m]: the region's plane at the cell
            centre where there is a region, else the height map, NaN where unknown.
        planes: (R, 4) float64 region planes ``(nx, ny, nz, d)`` with ``n . p + d = 0``.
        osrm: (H, W) float32 OSRM summed over orientations; zero where nothing is reachable.
    """

    robot: str
    points: NDArray[np.float32]
    origin: tuple[float, float]
    resolution: float
    labels: NDArray[np.int16]
    heights: NDArray[np.float32]
    planes: NDArray[np.float64]
    osrm: NDArray[np.float32]

    def __post_init__(self) -> None:
        shape = self.labels.shape
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise InputError(f"view data: points must be (N, 3), got {self.points.shape}")
        if len(shape) != 2 or self.heights.shape != shape or self.osrm.shape != shape:
            raise InputError(
                f"view data: labels {shape}, heights {self.heights.shape} and osrm {self.osrm.shape} "
                "must be the same (H, W) grid"
            )
        if self.planes.ndim != 2 or self.planes.shape[1] != 4:
            raise InputError(f"view data: planes must be (R, 4), got {self.planes.shape}")
        if shape[0] * shape[1] and int(self.labels.max(initial=-1)) >= len(self.planes):
            raise InputError(f"view data: a label exceeds the {len(self.planes)} region planes")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise InputError(f"view data: resolution must be positive, got {self.resolution}")
        if not self.robot:
            raise InputError("view data: no robot name")


def view_data_from(
    terrain: Terrain,
    osrm: OSRM | ArrayLike | None,
    points: ArrayLike,
    robot_name: str,
    max_points: int = MAX_POINTS,
    seed: int = 0,
) -> ViewData:
    """The view data of a segmented scene and its OSRM.

    Args:
        terrain: the segmented scene (its height map and regions).
        osrm: the OSRM over ``terrain``'s segmentation, or its (H, W) summed grid, or None (no heat map).
        points: (N, 3) world cloud [m]; a random subset of ``max_points`` is kept.
        robot_name: robot name or robot-file path (what ``Robot()`` takes).
        max_points: most cloud points kept.
        seed: seed of the subsampling.
    """
    seg = terrain.segmentation
    hmap = seg.hmap
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) > max_points:
        keep = np.sort(np.random.default_rng(seed).choice(len(pts), max_points, replace=False))
        pts = pts[keep]
    heights = np.asarray(hmap.raw, dtype=np.float64).copy()
    X, Y = hmap.cell_centres()
    for region in seg.regions:
        sel = seg.labels == region.id
        heights[sel] = region.height_at(np.c_[X[sel], Y[sel]])
    planes = np.array([[*r.normal, r.d] for r in seg.regions], dtype=np.float64).reshape(-1, 4)
    if osrm is None:
        summed = np.zeros(hmap.shape, dtype=np.float32)
    elif hasattr(osrm, "summed"):
        summed = np.asarray(osrm.summed, dtype=np.float32)
    else:
        summed = np.asarray(osrm, dtype=np.float32)
    if summed.shape != hmap.shape:
        raise InputError(f"the OSRM grid {summed.shape} is not the segmentation's {hmap.shape}")
    return ViewData(
        robot=robot_name,
        points=np.ascontiguousarray(pts),
        origin=(float(hmap.origin[0]), float(hmap.origin[1])),
        resolution=float(hmap.resolution),
        labels=seg.labels.astype(np.int16),
        heights=heights.astype(np.float32),
        planes=planes,
        osrm=np.nan_to_num(summed, nan=0.0).astype(np.float32),
    )


def save_view_data(path: str | Path, data: ViewData) -> None:
    """Write ``data`` to ``path`` as a compressed ``.npz`` (atomically; no pickled objects).

    Raises:
        InputError: the directory does not exist.
    """
    path = Path(path)
    with atomic_write(path, "view data") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(
            fh,
            version=np.array(VIEW_DATA_VERSION, dtype=np.int64),
            robot=np.array(data.robot),
            points=data.points.astype(np.float32),
            origin=np.array(data.origin, dtype=np.float64),
            resolution=np.array(data.resolution, dtype=np.float64),
            labels=data.labels.astype(np.int16),
            heights=data.heights.astype(np.float32),
            planes=data.planes.astype(np.float64),
            osrm=data.osrm.astype(np.float32),
        )


def load_view_data(path: str | Path) -> ViewData:
    """Read view data written by :func:`save_view_data`.

    Raises:
        InputError: the file is missing, not a view-data ``.npz`` or of another version.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"view data {path} does not exist")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in _KEYS if k not in npz.files]
            if missing:
                raise InputError(
                    f"view data {path} lacks {missing}; rewrite it with this version of baseplace"
                )
            arrays = {k: npz[k] for k in _KEYS}
    except InputError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"cannot read view data {path}: {first}") from None
    if int(arrays["version"]) != VIEW_DATA_VERSION:
        raise InputError(
            f"view data {path} has version {int(arrays['version'])}, this baseplace reads {VIEW_DATA_VERSION}"
        )
    if arrays["robot"].dtype.kind != "U" or arrays["origin"].shape != (2,):
        raise InputError(f"view data {path} is malformed (robot name or origin)")
    return ViewData(
        robot=str(arrays["robot"]),
        points=arrays["points"].astype(np.float32),
        origin=(float(arrays["origin"][0]), float(arrays["origin"][1])),
        resolution=float(arrays["resolution"]),
        labels=arrays["labels"].astype(np.int16),
        heights=arrays["heights"].astype(np.float32),
        planes=arrays["planes"].astype(np.float64),
        osrm=arrays["osrm"].astype(np.float32),
    )


def _stride(n_cells: int) -> int:
    return max(1, math.ceil(math.sqrt(n_cells / MAX_CELLS)))


def cell_quads(
    data: ViewData, rows: NDArray[np.int64], cols: NDArray[np.int64], lift: float, stride: int = 1
) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """One horizontal-footprint quad per cell on its region's plane, ``lift`` above it.

    Cells without a region sit flat at their height. ``stride`` > 1 draws cells that many times
    larger (the caller picks every stride-th cell).

    Returns:
        (4 N, 3) vertices and (2 N, 3) faces, counter-clockwise seen from above.
    """
    res = data.resolution * stride
    x0 = data.origin[0] + cols * data.resolution
    y0 = data.origin[1] + rows * data.resolution
    cx = np.stack([x0, x0 + res, x0 + res, x0], axis=1)
    cy = np.stack([y0, y0, y0 + res, y0 + res], axis=1)
    label = data.labels[rows, cols].astype(np.int64)
    z = np.repeat(np.nan_to_num(data.heights[rows, cols], nan=0.0).astype(np.float64)[:, None], 4, axis=1)
    has = label >= 0
    if has.any() and len(data.planes):
        pl = data.planes[label[has]]
        z[has] = -(pl[:, 3:4] + pl[:, 0:1] * cx[has] + pl[:, 1:2] * cy[has]) / pl[:, 2:3]
    verts = np.stack([cx, cy, z + lift], axis=2).reshape(-1, 3).astype(np.float32)
    base = (np.arange(len(rows), dtype=np.uint32) * 4)[:, None]
    faces = (base + np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32)).reshape(-1, 3)
    return verts, faces


def _cells(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    stride = _stride(int(mask.sum()))
    sub = np.zeros_like(mask)
    sub[::stride, ::stride] = mask[::stride, ::stride]
    rows, cols = np.nonzero(sub)
    return rows.astype(np.int64), cols.astype(np.int64), stride


def height_at(data: ViewData, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Surface height [m] under points (N, 2): the region plane, else the height map, else 0."""
    col = np.floor((xy[:, 0] - data.origin[0]) / data.resolution).astype(np.int64)
    row = np.floor((xy[:, 1] - data.origin[1]) / data.resolution).astype(np.int64)
    h, w = data.labels.shape
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    out = np.zeros(len(xy))
    r, c = row[inside], col[inside]
    label = data.labels[r, c].astype(np.int64)
    z = np.nan_to_num(data.heights[r, c].astype(np.float64), nan=0.0)
    has = label >= 0
    if has.any():
        pl = data.planes[label[has]]
        pts = xy[inside][has]
        z[has] = -(pl[:, 3] + pl[:, 0] * pts[:, 0] + pl[:, 1] * pts[:, 1]) / pl[:, 2]
    out[inside] = z
    return out
