"""Greedy thinning of a point cloud in the points' order (for :mod:`grasped_object`).

A point is kept unless an earlier kept point lies within ``spacing``; every point is owned by the
first kept point within ``spacing`` (itself when kept). Only distances and the order decide, so
the result does not depend on the frame of the points: the numba kernel's cells only find the
candidates within ``spacing`` quickly, every decision is an exact distance test. Clouds under
:data:`KERNEL_FROM` points go through a KD-tree loop instead (no kernel to load in a fresh
process); both give the same result.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from baseplace.geometry.poses import FloatArray
from baseplace.lazy import lazy_njit

KERNEL_FROM = 20_000
"""Clouds with at least this many points are thinned by the numba kernel."""


def thin_in_order(points: FloatArray, spacing: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(kept indices (K,) in order, owner of each point (N,) as a position in the kept indices).

    Args:
        points: (N, 3) finite points [m].
        spacing: [m] > 0.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    owner = _owners_kernel(p, spacing) if len(p) >= KERNEL_FROM else _owners_tree(p, spacing)
    kept = np.flatnonzero(owner == np.arange(len(p)))
    return kept, np.searchsorted(kept, owner).astype(np.intp)


def _owners_tree(p: FloatArray, spacing: float) -> NDArray[np.int64]:
    """The owner (N,) of every point as a point index, with a KD-tree and a loop over the kept points."""
    from scipy.spatial import cKDTree

    n = len(p)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    tree = cKDTree(p)
    nearest = tree.query(p, k=2)[0][:, 1] if n > 1 else np.full(n, np.inf)
    owner = np.where(nearest > spacing, np.arange(n), -1)  # a point with no neighbour keeps itself
    for i in np.flatnonzero(owner < 0).tolist():
        if owner[i] >= 0:  # covered by an earlier kept point
            continue
        ball = np.asarray(tree.query_ball_point(p[i], spacing), dtype=np.intp)
        owner[ball[owner[ball] < 0]] = i
    return owner.astype(np.int64)


def _owners_kernel(p: FloatArray, spacing: float) -> NDArray[np.int64]:
    """As :func:`_owners_tree`, in the numba kernel: candidates from cells of edge ``spacing``."""
    cells = sorted_cells(p, spacing, 1)
    if cells is None:  # too wide for its cells' keys
        return _owners_tree(p, spacing)
    return np.asarray(_thin(p, spacing * spacing, *cells))


def sorted_cells(
    p: FloatArray, edge: float, margin: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.intp]] | None:
    """The cells of edge ``edge`` [m] holding the points (N, 3), for a kernel's neighbour search.

    Returns each point's cell (N, 3), counted from ``margin`` empty cells below the lowest; the
    grid's size (3,), ``margin`` empty cells above the highest included; the points' cell keys
    (row-major in that grid) sorted; and the order (N,) that sorts them (stable). None when the
    grid holds 2**62 cells or more: its keys would overflow (points kilometres apart at
    centimetre cells), and the caller takes another way; None for no points too (no grid).
    """
    if len(p) == 0:
        return None
    lo, hi = np.floor(p.min(axis=0) / edge), np.floor(p.max(axis=0) / edge)
    if float(np.prod(hi - lo + 2 * margin + 1)) >= 2.0**62:
        return None
    cells = np.floor(p / edge).astype(np.int64)
    cells -= cells.min(axis=0) - margin
    dims = cells.max(axis=0) + margin + 1
    keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    return cells, dims, keys[order], order


@lazy_njit
def _thin(p, spacing2, cells, dims, sorted_keys, order):  # pragma: no cover - compiled
    n = len(p)
    owner = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if owner[i] >= 0:
            continue
        owner[i] = i
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    key = ((cells[i, 0] + dx) * dims[1] + cells[i, 1] + dy) * dims[2] + cells[i, 2] + dz
                    k = np.searchsorted(sorted_keys, key)
                    while k < n and sorted_keys[k] == key:
                        j = order[k]
                        k += 1
                        if owner[j] >= 0:
                            continue
                        d0, d1, d2 = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
                        if d0 * d0 + d1 * d1 + d2 * d2 <= spacing2:
                            owner[j] = i
    return owner
