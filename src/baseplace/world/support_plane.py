"""The surface under the grasped object as a thin slab, not voxels (issue 20, protocol v3).

An occupied 25 mm voxel is a whole cube: the voxel layer of a table top reaches up to 25 mm above
the true top, depending on where the top falls in the grid. A side grasp's hand, walking back
along its approach a centimetre or two above the table, meets that layer while the true table is
free (``bench/bench_execution.py``, protocol v2: most failed draws were ``no_motion`` for this
reason). Here the points of the planar support surface around the grasped object are fitted by a
plane, and the voxels those points alone occupy are replaced by one convex slab: the convex hull of
the points' footprint, from the plane less ``max(margin, voxel)`` up to the plane plus
``margin``, where ``margin`` is the 99th percentile of the points' vertical residuals (at least
:data:`MIN_MARGIN`). A voxel is replaced only when *every* cloud point in it lies inside the slab;
every other voxel stays, so every point of the cloud is still inside some obstacle. When the fit
is poor (too few points, a residual above :data:`MAX_RESIDUAL`, a plane tilted more than
:data:`MAX_TILT`) nothing is replaced.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import coal
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
MAX_RESIDUAL = 0.01
"""A fit whose 99th percentile of |residual| exceeds this [m] is not a plane: no slab."""
MIN_MARGIN = 0.003
"""The slab's top lies at least this far [m] above the fitted plane."""
MAX_TILT = math.radians(10.0)
"""A fitted plane tilted more than this from horizontal is not a support: no slab."""


@dataclass(frozen=True)
class SupportSlab:
    """A convex slab around a fitted support plane z = a x + b y + c (world frame).

    Attributes:
        coeffs: (a, b, c) of the plane.
        margin: the slab's top lies ``margin`` [m] above the plane.
        depth: its bottom lies ``depth`` [m] below the plane.
        hull: (H, 2) the footprint's convex hull, counter-clockwise [m].
        residual_p99: 99th percentile of the fitted points' |vertical residual| [m].
        points: how many points were fitted.
        geometry: the slab as a coal convex in the world frame.
    """

    coeffs: FloatArray
    margin: float
    depth: float
    hull: FloatArray
    residual_p99: float
    points: int
    geometry: coal.ConvexBase

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
                "residual_p99": round(self.residual_p99, 4), "points": self.points,
                "hull_vertices": len(self.hull)}  # fmt: skip


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
    counts = np.bincount(np.floor((z - z.min()) / BIN).astype(np.int64))
    mode = z.min() + (int(np.argmax(counts)) + 0.5) * BIN
    p = p[np.abs(z - mode) <= BAND]
    if len(p) < MIN_POINTS:
        return None
    A = np.c_[p[:, :2], np.ones(len(p))]
    coeffs, *_ = np.linalg.lstsq(A, p[:, 2], rcond=None)
    residual = p[:, 2] - A @ coeffs
    # one trimmed refit: points farther than 3 robust sigmas (the object's foot, a rim) are not
    # the plane; they may stay outside the slab, and their voxels then stay voxels
    sigma = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
    inlier = np.abs(residual) <= max(3 * sigma, MIN_MARGIN)
    if inlier.sum() < MIN_POINTS:
        return None
    p, A = p[inlier], A[inlier]
    coeffs, *_ = np.linalg.lstsq(A, p[:, 2], rcond=None)
    residual = p[:, 2] - A @ coeffs
    p99 = float(np.percentile(np.abs(residual), 99))
    tilt = math.atan(math.hypot(coeffs[0], coeffs[1]))
    if p99 > MAX_RESIDUAL or tilt > MAX_TILT:
        return None
    margin = max(p99, MIN_MARGIN)
    depth = max(margin, voxel)
    kept = p[np.abs(residual) <= margin]
    try:
        hull = kept[ConvexHull(kept[:, :2]).vertices, :2]  # counter-clockwise in 2-D
    except (QhullError, ValueError):
        return None
    a, b, c = (float(v) for v in coeffs)
    top = hull[:, 0] * a + hull[:, 1] * b + c
    corners = np.concatenate([np.c_[hull, top + margin], np.c_[hull, top - depth]])
    vertices = coal.StdVec_Vec3s()
    for v in corners:
        vertices.append(v)
    geometry = coal.Convex.convexHull(vertices, False, "")
    return SupportSlab(np.array([a, b, c]), margin, depth, hull, p99, len(p), geometry)


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


def with_support_slab(
    groups: dict[str, VoxelMap], points: ArrayLike, slab: SupportSlab | None
) -> dict[str, VoxelMap | SupportSlab]:
    """The obstacle groups with the voxels the slab replaces taken out and the slab added as "support_plane"."""
    if slab is None:
        return dict(groups)
    out: dict[str, VoxelMap | SupportSlab] = {
        name: v.without(slab_voxels(v, points, slab)) for name, v in groups.items()
    }
    out[SUPPORT_PLANE] = slab
    return out


SUPPORT_PLANE = "support_plane"
"""Name of the slab's obstacle group in contact reports."""


def cylinder_distance(centre_xy: ArrayLike, radius: float) -> Callable[[FloatArray], FloatArray]:
    """Horizontal distance from an upright cylinder's footprint (for :func:`fit_support_slab`)."""
    c = np.asarray(centre_xy, dtype=float)[:2]

    def distance(xy: FloatArray) -> FloatArray:
        return np.asarray(np.maximum(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) - radius, 0.0), dtype=float)

    return distance
