"""Height maps: the highest occupied voxel centre per cell, then Gaussian smoothing (seed 000 VI).

A :class:`HeightMap` owns its geometry: cell ``(i, j)`` (row i along y, column j along x) covers
``[ox + j res, ox + (j + 1) res) x [oy + i res, oy + (i + 1) res)``; cells no voxel falls in are
NaN (unknown).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.guards import check_grid_size
from baseplace.terrain.voxels import VoxelMap

FloatArray = NDArray[np.float64]
MAX_CELLS = 25_000_000
BYTES_PER_CELL = 384.0
"""Peak bytes per height-map cell of a segmentation: the height map, its smoothing, the local
plane fits and the labels (measured: about 320 for both segmenters)."""


def check_cells(n_cols: float, n_rows: float, resolution: float, reserved_bytes: float = 0.0) -> None:
    """Refuse a height map of ``n_cols x n_rows`` cells before it is allocated.

    The limit is :data:`MAX_CELLS` and what ``$BASEPLACE_MAX_MEMORY_MB``, less ``reserved_bytes``
    (the cloud's voxelization), holds at :data:`BYTES_PER_CELL`.

    Raises:
        InputError: one line with the cell count and the limit.
    """
    cells = float(n_cols) * float(n_rows)
    check_grid_size(
        cells, BYTES_PER_CELL,
        f"the cloud spans {n_cols * resolution:.0f} x {n_rows * resolution:.0f} m: a height map of "
        f"{n_cols:.0f} x {n_rows:.0f} = {cells:.3g} cells at {resolution} m",
        "use a coarser --resolution or crop the cloud", reserved_bytes=reserved_bytes, max_count=MAX_CELLS,
    )  # fmt: skip


@dataclass(frozen=True)
class HeightMap:
    """A 2.5D grid of heights in the world frame (z up).

    Attributes:
        origin: (x, y) of the lower-left corner of cell (0, 0) [m].
        resolution: cell edge [m].
        raw: (H, W) highest voxel centre per cell [m], NaN where unknown.
        smooth: (H, W) ``raw`` after NaN-aware Gaussian smoothing [m].
    """

    origin: tuple[float, float]
    resolution: float
    raw: FloatArray
    smooth: FloatArray = field(repr=False)

    @classmethod
    def from_voxels(cls, voxels: VoxelMap, resolution: float = 0.05, sigma_cells: float = 1.0) -> HeightMap:
        """Height map of a voxel map.

        Args:
            voxels: occupied voxels.
            resolution: cell edge [m], at least the voxel edge (seed 000: 0.05 over 0.025).
            sigma_cells: standard deviation of the Gaussian smoothing in cells (0: none).

        Raises:
            InputError: a resolution out of range, or a grid over the limit (:func:`check_cells`).
        """
        if not (voxels.resolution - 1e-12 <= resolution <= 1.0):
            raise InputError(
                f"height map resolution must be between the voxel size {voxels.resolution} m and 1 m, got {resolution}"
            )
        centres = voxels.centres
        ij = np.floor(centres[:, :2] / resolution).astype(np.int64)
        lo = ij.min(axis=0)
        shape = ij.max(axis=0) - lo + 1
        check_cells(shape[0], shape[1], resolution)
        flat = (ij[:, 1] - lo[1]) * shape[0] + (ij[:, 0] - lo[0])  # row = y, column = x
        top = np.full(int(shape[0] * shape[1]), -np.inf)
        np.maximum.at(top, flat, centres[:, 2])
        top[np.isneginf(top)] = np.nan
        raw = top.reshape(int(shape[1]), int(shape[0]))
        origin = (float(lo[0] * resolution), float(lo[1] * resolution))
        return cls(origin, float(resolution), raw, smooth_nan(raw, sigma_cells))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W): rows along y, columns along x."""
        h, w = self.raw.shape
        return h, w

    @property
    def known(self) -> NDArray[np.bool_]:
        """(H, W) True where some voxel fell in the cell."""
        return np.isfinite(self.raw)

    def cell_centres(self) -> tuple[FloatArray, FloatArray]:
        """World x (H, W) and y (H, W) of every cell centre."""
        h, w = self.shape
        xs = self.origin[0] + (np.arange(w) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(h) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)

    def centres_at(self, rows: ArrayLike, cols: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """World x (N,) and y (N,) of the centres of cells (rows (N,), cols (N,)): :meth:`cell_centres` there.

        The same values, bit for bit, without the (H, W) grids: a candidate needs one cell's centre.
        """
        r = np.asarray(rows, dtype=np.int64)
        c = np.asarray(cols, dtype=np.int64)
        x: FloatArray = self.origin[0] + (c.astype(np.float64) + 0.5) * self.resolution
        y: FloatArray = self.origin[1] + (r.astype(np.float64) + 0.5) * self.resolution
        return x, y

    def cell_of(self, xy: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        """Row, column and in-bounds flag of world points (N, 2)."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        col = np.floor((p[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        row = np.floor((p[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        inside = (row >= 0) & (col >= 0) & (row < self.shape[0]) & (col < self.shape[1])
        return row, col, inside


def smooth_nan(values: FloatArray, sigma_cells: float) -> FloatArray:
    """Gaussian smoothing that ignores NaN cells (normalized convolution) and keeps them NaN."""
    from scipy import ndimage  # here: a cached terrain never imports it (0.5 s)

    known = np.isfinite(values)
    if sigma_cells <= 0:
        return values.copy()
    filled = np.where(known, values, 0.0)
    num = ndimage.gaussian_filter(filled, sigma_cells, mode="constant")
    den = ndimage.gaussian_filter(known.astype(float), sigma_cells, mode="constant")
    out = np.full_like(values, np.nan)
    np.divide(num, den, out=out, where=known & (den > 1e-9))
    return out
