"""The surface under the grasped object cut down to a thin slab around its plane (issue 20, protocol v3).

An occupied 25 mm voxel is a whole cube: the voxel layer of a table top reaches up to 25 mm above
the true top, depending on where the top falls in the grid, and a single noisy point just above a
voxel boundary adds a cube reaching 25 mm higher. A side grasp's hand, walking back along its
approach a centimetre or two above the table, meets those cubes while the true table is free
(``bench/bench_execution.py``, protocol v2: most failed draws were ``no_motion`` for this reason).

Here the points of the planar support surface around the grasped object are fitted by a plane
(:func:`fit_support_slab`); the slab around it reaches from the plane less ``max(margin, voxel)``
up to the plane plus ``margin``, the largest vertical residual of the plane's points (those within
:data:`PLANE_SIGMAS` robust standard deviations of it; at least :data:`MIN_MARGIN`), over the
convex hull of their footprint. A voxel all of whose cloud points lie in the slab is cut down to
the heights it shares with the slab and filled with finer cells (:func:`clipped_cells`): each of
its points lies in both the voxel and the slab, so the model stays conservative for every point,
and it is never higher than the voxel nor than the slab. Every other voxel stays as it is. When
the fit is poor (too few points; a 99th percentile of the residuals of the points above the plane
over :data:`P99_SIGMAS` robust standard deviations of the plane's points, or that deviation over
:data:`MAX_SIGMA`; a plane tilted more than :data:`MAX_TILT`) nothing changes. Points below
the plane do not count there: they lie inside the slab (and the exact plane's prism), as the
table's side faces do near its edge.

The checks of ``place`` no longer cut voxels down to the slab (issue 25): they take the fit's plane
as an exact plane and its noise (:attr:`SupportSlab.sigma`) for the clearance
(:mod:`baseplace.world.sensor_resolution`), except where the surface is raised within the plane's
band (:func:`uneven_points`: a mat, a board), whose points stay cells. :func:`with_support_slab`
stays for the experiments that measured the slab (``baseplace_experiments.execution_experiment``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from baseplace.geometry.poses import FloatArray
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.grasped_object import rows_in

RADIUS = 0.5
"""Points within this horizontal distance [m] of the object's footprint are fitted: the hand's
0.15 m approach plus its length (TIAGo's safety box is 0.2 m long) and some of the transit."""
DEPTH = 0.1
"""How far [m] below the object's bottom the support surface is sought (as ``SUPPORT_DEPTH``)."""
BIN = 0.005
"""Height bin [m] of the densest layer that seeds the fit."""
BAND = 0.015
"""Points within this height [m] of the densest layer are fitted."""
MIN_POINTS = 50
"""Fewer fitted points than this: no slab."""
P99_SIGMAS = 3.5
"""A fit whose 99th percentile of the residuals above the plane exceeds this many of its robust standard
deviations is not a plane: no slab. The plane's points lie within :data:`PLANE_SIGMAS` of it; Gaussian
noise puts the 99th percentile at 2.58 and leaves 0.04 % of them between 3.5 and 4, so the test fires
on what stands on the plane or sticks out of it, at any noise level (the find-rate generator's dev
scenes, 2-8 mm noise: 1.7-3.35, bench/results/support_plane_ratios_dev.json). The limit is at least
:data:`MIN_MARGIN`, the band the plane's points are taken from when the noise is smaller (a noiseless
cloud). A raised part of the surface within the band can pass it; :func:`uneven_points` finds it.
Until session 20 the limit was 10 mm whatever the noise: at 4 mm it refused 28 of 30 dev tables and
at 5 mm all."""
MAX_SIGMA = 0.005
"""A fit whose robust standard deviation exceeds this [m] is not a plane: no slab. A third of
:data:`BAND`: the fitted window then holds 3 sigma of the noise either side of the surface, so the
residuals are not cut off (at 8 mm noise the window reads 5-6 mm); seed 000's 25 mm noise stays
refused."""
MIN_MARGIN = 0.003
"""The slab's top lies at least this far [m] above the fitted plane."""
CLEARANCE_SIGMAS = 3.0
"""The derived clearance is this many standard deviations of the scene's noise
(:func:`~baseplace.world.sensor_resolution.derived_clearance`); here, below both the sensor-resolution
model and the fitted neighbours (:mod:`~baseplace.world.neighbour_shapes`), which read it."""
PLANE_SIGMAS = 4.0
"""Points within this many robust standard deviations of the fitted plane are its points."""
FINE_PER_VOXEL = 5
"""A voxel cut down to the slab is filled with cells this many times finer (25 mm voxels: 5 mm)."""
MAX_TILT = math.radians(10.0)
"""A fitted plane tilted more than this from horizontal is not a support: no slab."""
UNEVEN = 0.0015
"""The exact plane stands for the surface only where the plane's points around lie this close [m] to
it on average, with 3 standard errors (:func:`uneven_points`): half the smallest clearance kept from
the plane (:data:`~baseplace.world.sensor_resolution.MIN_CLEARANCE`, 3 mm), so that a hand kept
that far above the plane stays at least this far above the surface."""
UNEVEN_CELL = 0.01
"""The cell [m] in which :func:`uneven_points` sums the plane's residuals."""


@dataclass(frozen=True)
class SupportSlab:
    """A convex slab around a fitted support plane z = a x + b y + c (world frame).

    Attributes:
        coeffs: (a, b, c) of the plane.
        margin: the slab's top lies ``margin`` [m] above the plane.
        depth: its bottom lies ``depth`` [m] below the plane.
        hull: (H, 2) the footprint's convex hull, counter-clockwise [m].
        residual_p99: 99th percentile of the vertical residuals of the plane's points above it [m].
        points: how many points were fitted.
        sigma: the robust standard deviation (median absolute deviation) of the plane's points'
            vertical residuals [m]: the sensor's noise, from which the clearance is derived
            (:func:`~baseplace.world.sensor_resolution.derived_clearance`).
    """

    coeffs: FloatArray
    margin: float
    depth: float
    hull: FloatArray
    residual_p99: float
    points: int
    sigma: float

    def height(self, xy: ArrayLike) -> FloatArray:
        """The plane's height (N,) [m] at xy points (N, 2)."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        a, b, c = self.coeffs
        return np.asarray(a * p[:, 0] + b * p[:, 1] + c, dtype=float)

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """(N,) True for the points (N, 3) inside the slab."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        r = p[:, 2] - self.height(p[:, :2])
        inside = (r <= self.margin) & (r >= -self.depth)
        h = self.hull
        for k in range(len(h)):  # left of every counter-clockwise edge (with a 1e-9 m tolerance)
            e = h[(k + 1) % len(h)] - h[k]
            inside &= e[0] * (p[:, 1] - h[k, 1]) - e[1] * (p[:, 0] - h[k, 0]) >= -1e-9 * np.hypot(*e)
        return inside

    def to_json(self) -> dict[str, float | int]:
        """What replaced the support's voxels, for results files."""
        return {"margin": round(self.margin, 4), "depth": round(self.depth, 4),
                "residual_p99": round(self.residual_p99, 4), "sigma": round(self.sigma, 5), "points": self.points,
                "hull_vertices": len(self.hull)}  # fmt: skip


def plane_points(
    points: ArrayLike,
    distance: Callable[[FloatArray], FloatArray],
    bottom: float,
    voxel: float,
    radius: float = RADIUS,
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """The plane fitted under an object, before its quality is judged; None with too few points.

    Returns (a, b, c) of z = a x + b y + c, the plane's points (P, 3) [m] and their vertical
    residuals (P,) [m]. :func:`fit_support_slab`'s fit (its arguments): the densest height layer, least squares with one
    trimmed refit, the points within :data:`PLANE_SIGMAS` robust sigmas of the plane.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    p = p[(p[:, 2] >= bottom - DEPTH) & (p[:, 2] <= bottom + voxel / 2)]
    if len(p) < MIN_POINTS:
        return None
    d = distance(p[:, :2])
    p = p[(d > 0) & (d <= radius)]
    if len(p) < MIN_POINTS:
        return None
    z = p[:, 2]
    p = p[np.abs(z - densest_height(z)) <= BAND]
    if len(p) < MIN_POINTS:
        return None
    A = np.c_[p[:, :2], np.ones(len(p))]
    coeffs, *_ = np.linalg.lstsq(A, p[:, 2], rcond=None)
    # one trimmed refit: points farther than 3 robust sigmas (the object's foot, a rim) do not
    # pull the plane
    residual = p[:, 2] - A @ coeffs
    inlier = np.abs(residual) <= max(3 * _robust_sigma(residual), MIN_MARGIN)
    if inlier.sum() < MIN_POINTS:
        return None
    coeffs, *_ = np.linalg.lstsq(A[inlier], p[inlier, 2], rcond=None)
    # the plane's points: within PLANE_SIGMAS robust sigmas of it (sensor noise); the slab holds
    # every one of them, the others (an object on the plane, a rare outlier) stay voxels
    residual = p[:, 2] - A @ coeffs
    plane = np.abs(residual) <= max(PLANE_SIGMAS * _robust_sigma(residual[inlier]), MIN_MARGIN)
    if plane.sum() < MIN_POINTS:
        return None
    return coeffs, p[plane], residual[plane]


def fit_support_slab(
    points: ArrayLike,
    distance: Callable[[FloatArray], FloatArray],
    bottom: float,
    voxel: float,
    radius: float = RADIUS,
) -> SupportSlab | None:
    """The slab of the planar surface an object stands on, or None when it is not a good plane.

    Args:
        points: (N, 3) the cloud [m].
        distance: horizontal distance (M,) [m] of xy points (M, 2) from the object's footprint
            (0 inside it); points inside the footprint are not fitted (they are the object).
        bottom: height [m] of the object's bottom; the surface is sought from :data:`DEPTH` below
            it to half a voxel above it.
        voxel: the voxel edge [m] the slab replaces; its bottom lies at least this far below the plane.
        radius: points within this distance [m] of the footprint are fitted.
    """
    fit = plane_points(points, distance, bottom, voxel, radius)
    if fit is None:
        return None
    coeffs, p, residual = fit
    # the plane's quality from the points above it: a point below it (the table's side faces within
    # BAND of its top, sampled near an edge) lies inside the exact plane's prism, so it cannot let a
    # link in, while it would push a two-sided percentile over the limit (with the 10 mm limit before
    # session 20, at 3 mm noise on table-grid execution dev seeds 0-2: 4 of 5 bottles near the
    # table's edge lost their plane)
    above = residual[residual > 0]
    p99 = float(np.percentile(above, 99)) if len(above) else 0.0
    tilt = math.atan(math.hypot(coeffs[0], coeffs[1]))
    sigma = _robust_sigma(residual)
    if p99 > max(P99_SIGMAS * sigma, MIN_MARGIN) or sigma > MAX_SIGMA or tilt > MAX_TILT:
        return None
    margin = max(float(np.abs(residual).max()), MIN_MARGIN)
    depth = max(margin, voxel)
    try:
        hull = p[ConvexHull(p[:, :2]).vertices, :2]  # counter-clockwise in 2-D
    except (QhullError, ValueError):
        return None
    a, b, c = (float(v) for v in coeffs)
    return SupportSlab(np.array([a, b, c]), margin, depth, hull, p99, len(p), sigma)


def uneven_points(slab: SupportSlab, points: ArrayLike, standing: ArrayLike = ()) -> NDArray[np.bool_]:
    """(N,) True for the points (N, 3) where the plane does not stand for the surface.

    A fit is tested as a whole (:func:`fit_support_slab`); a part of the surface raised within the
    plane's noise band (a mat, a board a few millimetres thick) still passes it, and its points would
    be taken for the plane's. So the surface is tested where it is: the points within ``slab.margin``
    of the plane (a symmetric window, so a flat surface's mean residual is 0) are summed in cells of
    :data:`UNEVEN_CELL`, and each cell reads the mean residual of the points in the square window
    around it that holds, on average, enough points for 3 standard errors of the mean to be a third
    of :data:`UNEVEN` (``(9 sigma / UNEVEN)**2`` points). A cell is uneven when that mean plus 3
    standard errors exceeds :data:`UNEVEN` (a window with few points, as at the plane's edges, is
    uneven unless its mean is well below; one short of half the points it should hold reads the
    window twice as wide), and so is every cell within a quarter window of one whose mean is more
    than 3 standard errors above the plane; every point in an uneven cell is. A cell with no point
    counted around it is not: its points are feet (below) or lie under the plane. A raised region
    wider than a window is uneven throughout and up to its edges (a window half on it reads half its
    height); a narrower one is uneven when its height times its share of the window exceeds about
    :data:`UNEVEN` / 3.

    ``standing`` (M, 3): points of things standing on the plane (the caller's: those more than two
    margins above it). The cells holding one, and their neighbours, are their feet: the foot of a
    wall lies in the plane's band, so its points are left out of the means (they would raise every
    window around a neighbour). A foot cell is uneven only when the window around it is.
    """
    from scipy.ndimage import binary_dilation, maximum_filter, uniform_filter

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0, dtype=bool)
    r = p[:, 2] - slab.height(p[:, :2])
    cell = np.floor(p[:, :2] / UNEVEN_CELL).astype(np.int64)
    lo = cell.min(axis=0)
    ij = cell - lo
    shape = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1)
    if shape[0] * shape[1] > 4 * len(p) + 10_000:  # points far apart: no cell holds enough of them
        return np.ones(len(p), dtype=bool)
    feet = np.zeros(shape, dtype=bool)
    up = np.asarray(standing, dtype=float).reshape(-1, 3)
    if len(up):
        k = np.floor(up[:, :2] / UNEVEN_CELL).astype(np.int64) - lo
        k = k[np.all((k >= 0) & (k < shape), axis=1)]
        feet[k[:, 0], k[:, 1]] = True
        feet = binary_dilation(feet, np.ones((3, 3), dtype=bool))
    counted = (np.abs(r) <= slab.margin) & ~feet[ij[:, 0], ij[:, 1]]
    flat = np.ravel_multi_index((ij[counted, 0], ij[counted, 1]), shape)
    count = np.bincount(flat, minlength=shape[0] * shape[1]).reshape(shape).astype(float)
    total = np.bincount(flat, weights=r[counted], minlength=shape[0] * shape[1]).reshape(shape)
    sigma = max(slab.sigma, 1e-4)
    need = (9.0 * sigma / UNEVEN) ** 2
    per_cell = count[count > 0].mean() if (count > 0).any() else 1.0
    side = 2 * math.ceil(0.5 * (math.sqrt(need / per_cell) - 1.0)) + 1  # odd: centred on the cell
    n = uniform_filter(count, side, mode="constant") * side**2
    s = uniform_filter(total, side, mode="constant") * side**2
    wide = 2 * side + 1  # where feet, the object or the plane's edge leave the window short of points
    short = n < need / 2
    n = np.where(short, uniform_filter(count, wide, mode="constant") * wide**2, n)
    s = np.where(short, uniform_filter(total, wide, mode="constant") * wide**2, s)
    m = np.maximum(n, 1.0)
    mean, error = s / m, sigma / np.sqrt(m)
    # no point counted around: a foot, or under the plane
    uneven = (n >= 0.5) & (mean + 3.0 * error > UNEVEN)
    # evidently raised (not merely short of points): so is a quarter window around
    raised = uneven & (mean > 3.0 * error)
    uneven |= maximum_filter(raised, side // 2 | 1, mode="constant")
    return np.asarray(uneven[ij[:, 0], ij[:, 1]], dtype=bool)


def densest_height(z: FloatArray, bin_size: float = BIN) -> float:
    """The centre [m] of the most populated height bin of the heights (N,) [m], N >= 1: a surface's level."""
    counts = np.bincount(np.floor((z - z.min()) / bin_size).astype(np.int64))
    return float(z.min() + (int(np.argmax(counts)) + 0.5) * bin_size)


def _robust_sigma(residual: FloatArray) -> float:
    """The standard deviation of Gaussian residuals (N,) from their median absolute deviation."""
    return 1.4826 * float(np.median(np.abs(residual - np.median(residual))))


def slab_voxels(voxels: VoxelMap, points: ArrayLike, slab: SupportSlab) -> NDArray[np.bool_]:
    """(M,) True for the voxels the slab replaces: those holding a point, every one inside the slab."""
    if len(voxels) == 0:
        return np.zeros(0, dtype=bool)
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    lo, hi = slab.hull.min(axis=0) - voxels.resolution, slab.hull.max(axis=0) + voxels.resolution
    p = p[np.all((p[:, :2] >= lo) & (p[:, :2] <= hi), axis=1)]
    if len(p) == 0:
        return np.zeros(len(voxels), dtype=bool)
    keys = np.floor(p / voxels.resolution).astype(np.int64)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    outside = np.zeros(len(uniq), dtype=bool)
    np.logical_or.at(outside, inverse.reshape(-1), ~slab.contains(p))
    replaced = uniq[~outside]
    if len(replaced) == 0:
        return np.zeros(len(voxels), dtype=bool)
    return rows_in(voxels.keys, replaced)


def clipped_cells(voxels: VoxelMap, slab: SupportSlab) -> tuple[NDArray[np.bool_], VoxelMap]:
    """The voxels cut down to the slab: (M,) True for the voxels replaced, and the finer cells replacing them.

    Each voxel the slab replaces (:func:`slab_voxels` is the caller's choice of ``voxels``) that
    reaches above the slab's top or below its bottom over its square is cut to the heights both
    share, [max(voxel bottom, slab bottom), min(voxel top, slab top)] (the slab's extremes over the
    square's corners), and filled with cells :data:`FINE_PER_VOXEL` times finer: every one of its
    points lies in both the voxel and the slab, so in a cell. A voxel inside the slab stays as it is.
    """
    res = voxels.resolution
    n = FINE_PER_VOXEL
    fine = res / n
    if len(voxels) == 0:
        return np.zeros(0, dtype=bool), VoxelMap(fine, np.zeros((0, 3), dtype=np.int64))
    k = voxels.keys
    corners = np.concatenate([(k[:, :2] + np.array(o)) * res for o in ((0, 0), (1, 0), (0, 1), (1, 1))])
    plane = slab.height(corners).reshape(4, -1)
    top = plane.max(axis=0) + slab.margin
    bottom = plane.min(axis=0) - slab.depth
    z0, z1 = k[:, 2] * res, (k[:, 2] + 1) * res
    lo, hi = np.maximum(z0, bottom), np.minimum(z1, top)
    cut = (hi > lo) & ((lo > z0 + 1e-9) | (hi < z1 - 1e-9))
    cells = []
    sub = np.array([(i, j) for i in range(n) for j in range(n)], dtype=np.int64)
    for key, a, b in zip(k[cut], lo[cut], hi[cut], strict=True):
        layers = np.arange(int(np.floor(a / fine)), max(int(np.ceil(b / fine)), int(np.floor(a / fine)) + 1))
        xy = key[:2] * n + sub
        cells.append(np.c_[np.repeat(xy, len(layers), axis=0), np.tile(layers, len(xy))])
    keys = np.unique(np.concatenate(cells), axis=0) if cells else np.zeros((0, 3), dtype=np.int64)
    return cut, VoxelMap(fine, keys.astype(np.int64))


def with_support_slab(
    groups: dict[str, VoxelMap], points: ArrayLike, slab: SupportSlab | None
) -> dict[str, VoxelMap]:
    """The obstacle groups with the voxels the slab replaces cut down to it (:func:`clipped_cells`).

    The cut voxels leave their groups; their finer cells form the group :data:`SUPPORT_PLANE`.
    """
    if slab is None:
        return dict(groups)
    out: dict[str, VoxelMap] = {}
    fine: list[NDArray[np.int64]] = []
    for name, v in groups.items():
        replaced = np.flatnonzero(slab_voxels(v, points, slab))
        cut, cells = clipped_cells(VoxelMap(v.resolution, v.keys[replaced]), slab)
        mask = np.zeros(len(v), dtype=bool)
        mask[replaced[cut]] = True
        out[name] = v.without(mask)
        fine.append(cells.keys)
        resolution = cells.resolution
    if fine and sum(len(f) for f in fine):
        out[SUPPORT_PLANE] = VoxelMap(resolution, np.unique(np.concatenate(fine), axis=0))
    return out


SUPPORT_PLANE = "support_plane"
"""Name of the obstacle group of the voxels cut down to the slab, in contact reports."""


def cylinder_distance(centre_xy: ArrayLike, radius: float) -> Callable[[FloatArray], FloatArray]:
    """Horizontal distance from an upright cylinder's footprint (for :func:`fit_support_slab`)."""
    c = np.asarray(centre_xy, dtype=float)[:2]

    def distance(xy: FloatArray) -> FloatArray:
        return np.asarray(np.maximum(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) - radius, 0.0), dtype=float)

    return distance
