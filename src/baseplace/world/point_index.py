"""A point cloud indexed for sphere queries: is any point within a sphere, and how near is it?

The robot side of a scene check is a set of spheres (:mod:`baseplace.robots.spheres`); the scene
side here is the cloud's own points, not voxels, so a sphere is clear exactly when no measured
point lies within its radius plus the clearance. Two structures answer that:

* a **spatial hash** of the points: the points sorted by the cell of a uniform grid (``cell``
  metres) that they fall in, with the sorted keys of the occupied cells and where each cell's
  points start. A query visits the cells that the sphere's bounding box overlaps (a binary search
  each) and the points in them; the answer is exact.
* a **distance field** for an early out: the Euclidean distance transform of the occupied cells of
  a coarser dense grid (``field_resolution``) over the points' bounding box. At a query centre in
  cell ``v``, ``D(v) - h*sqrt(3)`` is a lower bound of the distance to the nearest point (the
  centre and that point each lie within half a diagonal of their cells' centres), so a sphere
  whose radius is below it is clear without visiting a point. Outside the field the distance to
  the points' bounding box is the bound.

Both answers are compared with ``scipy.spatial.cKDTree`` in ``tests/test_point_index.py``, and the
query time against it and against coal's octree in ``bench/bench_point_index.py``. This is the
point structure of the issue "Find the grasps that are there" (sensor-resolution collision), made
for spheres the way VAMP's collision-affording point trees (Ramsey et al., 2024) are.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from baseplace.errors import InputError
from baseplace.guards import check_grid_size

FIELD_BYTES_PER_CELL = 32.0
"""Peak bytes per cell of the distance field's build (scipy's transform: float64 out, int32 x 3 indices, flags)."""
MAX_FIELD_CELLS = 2_000_000
"""The distance field is made coarser until it has at most this many cells (8 MB of float32; about 0.5 s to build)."""


class PointIndex:
    """The points (N, 3) [m] of a scene indexed for sphere queries.

    Args:
        points: the scene's points in the world frame.
        cell: edge [m] of the spatial hash's cells; about the spheres' radius suits it.
        field_resolution: finest edge [m] of the distance field's cells (coarsened to stay within
            :data:`MAX_FIELD_CELLS`); 0 builds no field.

    Raises:
        InputError: points not of shape (N, 3) or not finite, or a cell size not positive.
    """

    def __init__(self, points: ArrayLike, cell: float = 0.02, field_resolution: float = 0.02) -> None:
        P = np.asarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise InputError(f"points must be of shape (N, 3), got {P.shape}")
        if not np.isfinite(P).all():
            raise InputError("points must be finite: the cloud holds NaN or infinite coordinates")
        if not (cell > 0 and math.isfinite(cell)):
            raise InputError(f"cell must be a positive length [m], got {cell}")
        self.cell = float(cell)
        self.n_points = len(P)
        self.lo = P.min(axis=0) if len(P) else np.zeros(3)
        self.hi = P.max(axis=0) if len(P) else np.zeros(3)
        self.dims = (
            (np.floor((self.hi - self.lo) / self.cell).astype(np.int64) + 1)
            if len(P)
            else np.ones(3, np.int64)
        )
        keys = _keys(P, self.lo, self.cell, self.dims)
        order = np.argsort(keys, kind="stable")
        self.points = np.ascontiguousarray(P[order])
        sorted_keys = keys[order]
        self.cell_keys, first = np.unique(sorted_keys, return_index=True)
        self.cell_starts = np.append(first, len(P)).astype(np.int64)
        self._field(field_resolution)

    def _field(self, resolution: float) -> None:
        """The distance field (or an empty one) of :class:`PointIndex`'s docstring."""
        self.field = np.zeros((0, 0, 0), dtype=np.float32)
        self.field_lo, self.field_h = self.lo.copy(), 0.0
        if resolution <= 0 or self.n_points == 0:
            return
        extent = self.hi - self.lo
        h = float(resolution)
        while float(np.prod(np.floor(extent / h) + 1)) > MAX_FIELD_CELLS:
            h *= 1.25
        shape = tuple(int(v) for v in np.floor(extent / h) + 1)
        check_grid_size(float(np.prod(shape, dtype=float)), FIELD_BYTES_PER_CELL,
                        f"a distance field of {' x '.join(map(str, shape))} cells", "use a coarser field")  # fmt: skip
        occupied = np.zeros(shape, dtype=bool)
        idx = np.minimum(np.floor((self.points - self.lo) / h).astype(np.int64), np.array(shape) - 1)
        occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        self.field = (ndimage.distance_transform_edt(~occupied) * h).astype(np.float32)
        self.field_h = h

    def clear(self, centers: ArrayLike, radii: ArrayLike, clearance: float = 0.0) -> NDArray[np.bool_]:
        """Per sphere (S,): True where no point lies within its radius plus ``clearance`` [m]."""
        C, R = self._spheres(centers, radii, clearance)
        out = np.empty(len(C), dtype=np.bool_)
        _clear(out, C, R, *self._arrays())
        return out

    def any_hit(self, centers: ArrayLike, radii: ArrayLike, clearance: float = 0.0) -> bool:
        """Whether any sphere holds a point within its radius plus ``clearance``; stops at the first."""
        C, R = self._spheres(centers, radii, clearance)
        return bool(_any_hit(C, R, *self._arrays()))

    def distances(self, centers: ArrayLike, up_to: float) -> NDArray[np.float64]:
        """Per centre (S,): the distance [m] to the nearest point, or ``inf`` where none is within ``up_to``."""
        C, _ = self._spheres(centers, np.zeros(len(np.atleast_2d(centers))), 0.0)
        out = np.empty(len(C), dtype=np.float64)
        _nearest(out, C, float(up_to), *self._arrays())
        return out

    def _spheres(
        self, centers: ArrayLike, radii: ArrayLike, clearance: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        C = np.ascontiguousarray(np.atleast_2d(np.asarray(centers, dtype=np.float64)))
        R = np.ascontiguousarray(
            np.broadcast_to(np.asarray(radii, dtype=np.float64) + float(clearance), (len(C),))
        )
        if C.shape[1] != 3:
            raise InputError(f"sphere centres must be of shape (S, 3), got {C.shape}")
        return C, R

    def _arrays(self) -> tuple[object, ...]:
        return (self.points, self.cell_keys, self.cell_starts, self.lo, self.hi, self.cell, self.dims,
                self.field, self.field_lo, self.field_h)  # fmt: skip


def _keys(
    P: NDArray[np.float64], lo: NDArray[np.float64], cell: float, dims: NDArray[np.int64]
) -> NDArray[np.int64]:
    ijk = np.minimum(np.floor((P - lo) / cell).astype(np.int64), dims - 1)
    return ijk[:, 0] + dims[0] * (ijk[:, 1] + dims[1] * ijk[:, 2])


@nb.njit(cache=True, inline="always")
def _lower_bound(c, lo, hi, field, field_lo, field_h):
    """A lower bound [m] of the distance from ``c`` to the nearest point (see the module docstring)."""
    d2 = 0.0
    for k in range(3):
        if c[k] < lo[k]:
            d2 += (lo[k] - c[k]) ** 2
        elif c[k] > hi[k]:
            d2 += (c[k] - hi[k]) ** 2
    bound = math.sqrt(d2)
    if field_h > 0.0 and d2 == 0.0:
        i = min(int((c[0] - field_lo[0]) / field_h), field.shape[0] - 1)
        j = min(int((c[1] - field_lo[1]) / field_h), field.shape[1] - 1)
        k = min(int((c[2] - field_lo[2]) / field_h), field.shape[2] - 1)
        bound = max(bound, field[i, j, k] - field_h * 1.7320508075688772)
    return bound


@nb.njit(cache=True, inline="always")
def _cell_range(c, e, lo, cell, dims):
    """The index's cells (i0, i1, j0, j1, k0, k1) that hold points within ``e`` of ``c`` (3,), clipped to the grid."""
    i0 = max(math.floor((c[0] - e - lo[0]) / cell), 0)
    i1 = min(math.floor((c[0] + e - lo[0]) / cell), dims[0] - 1)
    j0 = max(math.floor((c[1] - e - lo[1]) / cell), 0)
    j1 = min(math.floor((c[1] + e - lo[1]) / cell), dims[1] - 1)
    k0 = max(math.floor((c[2] - e - lo[2]) / cell), 0)
    k1 = min(math.floor((c[2] + e - lo[2]) / cell), dims[2] - 1)
    return i0, i1, j0, j1, k0, k1


@nb.njit(cache=True, inline="always")
def _seek(keys, u, v):
    """``np.searchsorted(keys, v)`` for sorted keys whose first u are all below v: galloping from u.

    The cells of one query are visited in increasing key order, so the next row's cells lie just
    after the last one read: a few steps from there instead of a binary search over every key.
    """
    n = len(keys)
    lo, hi, step = u, u, 1
    while hi < n and keys[hi] < v:  # keys[:lo] < v; stop at a key >= v or the end
        lo = hi + 1
        hi = lo + step
        step *= 2
    hi = min(hi, n)
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def _within(c, r, first, points, keys, starts, lo, cell, dims):
    """The squared distance to the nearest point within ``r`` of ``c`` (-1.0 when there is none).

    With ``first``, any point within ``r`` is returned (the search stops there). Cells whose box
    lies farther than ``r`` from ``c`` are passed over without reading their points.
    """
    r2 = r * r
    best = -1.0
    e = r + 1e-9  # the cells a point at exactly the radius lies in, whatever the rounding
    i0, i1, j0, j1, k0, k1 = _cell_range(c, e, lo, cell, dims)
    a = 0  # every key before a is below the next row's first (the rows come in increasing order)
    for k in range(k0, k1 + 1):
        dz = max(lo[2] + k * cell - c[2], c[2] - (lo[2] + (k + 1) * cell), 0.0)
        for j in range(j0, j1 + 1):
            dy = max(lo[1] + j * cell - c[1], c[1] - (lo[1] + (j + 1) * cell), 0.0)
            if dy * dy + dz * dz > r2 * (1.0 + 1e-9) + 1e-18:
                continue
            row = dims[0] * (j + dims[1] * k)
            a = _seek(keys, a, row + i0)  # the occupied cells of this row within [i0, i1]
            while a < len(keys) and keys[a] <= row + i1:
                i = keys[a] - row
                dx = max(lo[0] + i * cell - c[0], c[0] - (lo[0] + (i + 1) * cell), 0.0)
                if dx * dx + dy * dy + dz * dz <= r2 * (1.0 + 1e-9) + 1e-18:
                    for p in range(starts[a], starts[a + 1]):
                        d2 = (
                            (points[p, 0] - c[0]) ** 2
                            + (points[p, 1] - c[1]) ** 2
                            + (points[p, 2] - c[2]) ** 2
                        )
                        if d2 <= r2 and (best < 0.0 or d2 < best):
                            best = d2
                            if first:
                                return best
                a += 1
    return best


@nb.njit(cache=True)
def _hit(c, r, points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h):
    if len(points) == 0 or _lower_bound(c, lo, hi, field, field_lo, field_h) > r:
        return False
    return _within(c, r, True, points, keys, starts, lo, cell, dims) >= 0.0


@nb.njit(cache=True)
def _clear(out, C, R, points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h):
    for s in range(len(C)):
        out[s] = not _hit(C[s], R[s], points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h)


@nb.njit(cache=True)
def _any_hit(C, R, points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h):
    for s in range(len(C)):
        if _hit(C[s], R[s], points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h):
            return True
    return False


@nb.njit(cache=True)
def _nearest(out, C, up_to, points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h):
    for s in range(len(C)):
        out[s] = np.inf
        if len(points) == 0 or _lower_bound(C[s], lo, hi, field, field_lo, field_h) > up_to:
            continue
        d2 = _within(C[s], up_to, False, points, keys, starts, lo, cell, dims)
        if d2 >= 0.0:
            out[s] = math.sqrt(d2)
