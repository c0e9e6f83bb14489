"""Neighbour objects near the grasped object as fitted whole shapes: upright cylinders and boxes (issue 25).

A raw point at a neighbour bottle's rim keeps the whole clearance c (its own error is the noise,
u = n: :mod:`baseplace.world.sensor_resolution`), and local two-face fits of 8-20 points did not do
better (session 14). A whole neighbour holds hundreds of points: a shape fitted to all of them knows
where its surface lies to about sigma / sqrt(N), far below one point's noise, if the neighbour IS
that shape. Here the points near the object that are neither the object's nor the support plane's
are split into clusters (connected at :data:`LINK`, :func:`clusters`), and each standing on the
support plane is fitted by an upright cylinder and by a box
(:func:`~baseplace.world.primitive_fits.fit_cluster`: axis along the plane's normal, the bottom on
the plane). A fit is accepted only when the cluster fits it
(:func:`~baseplace.world.fit_acceptance.accepted`: coverage all around, no point outside its faces,
nothing under its top, every patch's, ring's, strip's and tile's mean close to its surface), and its
error u (:attr:`FittedShape.error`) is the fit's 3 standard errors plus the acceptance's allowance.
Features smaller than a patch and a few sigma proud can pass: that limit, measured, is in
:mod:`~baseplace.world.fit_acceptance`.

A fit's u may exceed n, the raw points' own: a 10 cm box's is 10.5 mm at n = 9 mm (its
corners from a footprint angle that is not refined). It is taken all the same: an exact solid has
no gaps between samples, where a sparse cloud's raw cells let spheres through at edges and rims
(tests/test_clearance_bound_spacing.py: its eight known holes close on the fitted neighbours; the
box at 9 and 12.5 mm spacing needs u >= n for that).

The accepted neighbour becomes an exact convex prism (:meth:`FittedShape.geometry`: the cylinder's
circumscribed :data:`~baseplace.world.fitted_shape.SEGMENTS`-gon, the box itself) kept at c - n + u
(:func:`~baseplace.world.sensor_resolution.margin`), and its points leave the fine cells; a rejected
cluster stays as it was.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from baseplace.geometry.poses import FloatArray
from baseplace.lazy import lazy_njit
from baseplace.world.fit_acceptance import POINT_SIGMAS, accepted
from baseplace.world.fitted_shape import FittedShape, noise_sigma
from baseplace.world.primitive_fits import fit_cluster
from baseplace.world.support_plane import SupportSlab
from baseplace.world.thinning import sorted_cells

__all__ = ["LINK", "MIN_POINTS", "FittedShape", "clusters", "fit_neighbours", "plane_frame"]

LINK = 0.02
"""Points closer than this [m] belong to one cluster: twice the 1 cm sampling of a neighbour."""
MIN_POINTS = 60
"""A cluster of fewer points is not fitted."""


def plane_frame(slab: SupportSlab) -> tuple[FloatArray, FloatArray]:
    """(origin (3,), axes (3, 3)) of the support plane: a point on it and columns along it and up its normal."""
    a, b, c = slab.coeffs
    normal = np.array([-a, -b, 1.0]) / math.sqrt(a * a + b * b + 1.0)
    e1 = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    e1 /= np.linalg.norm(e1)
    return np.array([0.0, 0.0, c]), np.c_[e1, np.cross(normal, e1), normal]


def clusters(points: ArrayLike, link: float = LINK) -> NDArray[np.int64]:
    """(N,) the connected component of each point (N, 3) [m], points at most ``link`` apart joined.

    Components are numbered in the order of their first point. Clouds of :data:`KERNEL_FROM`
    points or more go through a compiled kernel (:func:`_cell_components`); smaller ones through
    every pair within ``link`` (:func:`clusters_by_pairs`, the kernel's test oracle). A dense stereo
    cloud holds about a thousand pairs per point within 2 cm: 8.7 million pairs, 1.8 s, for
    the 16 586 points around the PCL mug.
    """
    p = np.ascontiguousarray(np.asarray(points, dtype=float).reshape(-1, 3))
    if len(p) < KERNEL_FROM:
        return clusters_by_pairs(p, link)
    # two points in one cell of edge h are closer than link, by 20 nm at 2 cm: more than the cells'
    # rounding (p / h in doubles) moves a point at UTM-sized coordinates (1e-10 m at 1e6 m)
    h = link / math.sqrt(3.0) * (1.0 - 1e-6)
    cells = sorted_cells(p, h, 2)
    if cells is None:  # too wide for its cells' keys
        return clusters_by_pairs(p, link)
    root = _cell_components(p, link * link, *cells)
    return np.unique(root, return_inverse=True)[1].astype(np.int64)  # roots are each component's first point


def clusters_by_pairs(points: ArrayLike, link: float = LINK) -> NDArray[np.int64]:
    """:func:`clusters` from every pair of points within ``link`` (a KD-tree) and a sparse graph."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(p).query_pairs(link, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(p), len(p)))
    return np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)


KERNEL_FROM = 10_000
"""Clouds of at least this many points are split into clusters by the compiled kernel."""


@lazy_njit
def _cell_components(p, link2, cells, dims, sorted_keys, order):  # pragma: no cover - compiled
    """Each point's component root (N,), the component's lowest point index: union-find over cells.

    The points of one cell (edge under link / sqrt 3) are joined without a test; two cells up to
    two apart along each axis are joined when their roots differ and some pair of their points
    lies within the link (squared: ``link2``), tested pair by pair until one does. Roots are
    found with path halving; a union hangs the higher root under the lower.
    """
    n = len(p)
    parent = np.arange(n)
    starts = np.empty(n + 1, dtype=np.int64)  # runs of one key in sorted_keys
    m = 0
    for k in range(n):
        if k == 0 or sorted_keys[k] != sorted_keys[k - 1]:
            starts[m] = k
            m += 1
    starts[m] = n
    for c in range(m):  # one cell: one component, under its lowest point
        low = order[starts[c]]
        for k in range(starts[c], starts[c + 1]):
            low = min(low, order[k])
        for k in range(starts[c], starts[c + 1]):
            parent[order[k]] = low
    for c in range(m):
        i0, c0, c1 = order[starts[c]], starts[c], starts[c + 1]
        for dx in range(-2, 3):
            for dy in range(-2, 3):
                for dz in range(-2, 3):
                    key = ((cells[i0, 0] + dx) * dims[1] + cells[i0, 1] + dy) * dims[2] + cells[i0, 2] + dz
                    if key <= sorted_keys[c0]:
                        continue  # each pair of cells once
                    b0 = np.searchsorted(sorted_keys, key)
                    if b0 == n or sorted_keys[b0] != key:
                        continue
                    ra, rb = i0, order[b0]
                    while parent[ra] != ra:
                        parent[ra] = parent[parent[ra]]
                        ra = parent[ra]
                    while parent[rb] != rb:
                        parent[rb] = parent[parent[rb]]
                        rb = parent[rb]
                    if ra == rb:
                        continue
                    b1 = b0
                    while b1 < n and sorted_keys[b1] == key:
                        b1 += 1
                    joined = False
                    for u in range(c0, c1):
                        i = order[u]
                        for v in range(b0, b1):
                            j = order[v]
                            d0, d1, d2 = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
                            if d0 * d0 + d1 * d1 + d2 * d2 <= link2:
                                joined = True
                                break
                        if joined:
                            break
                    if joined:
                        parent[max(ra, rb)] = min(ra, rb)
    for i in range(n):  # every point to its root
        r = i
        while parent[r] != r:
            r = parent[r]
        parent[i] = r
    return parent


def fit_neighbours(
    points: ArrayLike, slab: SupportSlab, noise_margin: float
) -> list[tuple[FittedShape, NDArray[np.int64]]]:
    """The accepted fits of the clusters of ``points`` (N, 3) [m], each with its points' indices.

    Per cluster of at least :data:`MIN_POINTS` standing on the plane (no point more than
    :data:`~baseplace.world.fit_acceptance.POINT_SIGMAS` sigma below it), the cylinder and the box
    (:func:`~baseplace.world.primitive_fits.fit_cluster`); of those
    :func:`~baseplace.world.fit_acceptance.accepted`, the one of smaller error.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    origin, axes = plane_frame(slab)
    sigma = noise_sigma(noise_margin)
    label = clusters(p)
    out = []
    for k in np.unique(label):
        rows = np.flatnonzero(label == k)
        if len(rows) < MIN_POINTS:
            continue
        L = (p[rows] - origin) @ axes
        if L[:, 2].min() < -POINT_SIGMAS * sigma:
            continue
        fits = [a for f in fit_cluster(L, origin, axes, noise_margin) if (a := accepted(f, L)) is not None]
        if fits:
            out.append((min(fits, key=lambda f: f.error), rows))
    return out
