"""Settings from the data and diagnoses of clouds that give no support surface.

Seed 000 segments a 25 mm OctoMap into a 50 mm height map: the right scale for a room scanned by
a robot. A head camera looking at a table sees 1-2 m of scene, in which a 0.6 x 0.4 m tabletop is
12 x 8 cells at 5 cm, and the 5 x 5-cell window of the local normals leaves a core of 8 x 4 = 32
planar cells, below the 40-cell minimum region: the table is lost. :func:`auto_resolution`
therefore picks the cell from the cloud's horizontal extent and point spacing.

A cloud in a camera frame (z forward) looks like a scene whose "support" is the back wall.
:func:`dominant_planes` (RANSAC on a voxel-thinned cloud) and :func:`check_up_direction` find
that case and name the likely up vector; :func:`explain_no_support` turns "no region found" into
its real cause (too small at this resolution, or no level plane at all).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.arrays import unique_ints_first
from baseplace.errors import InputError

FloatArray = NDArray[np.float64]

MIN_AUTO_RESOLUTION, MAX_AUTO_RESOLUTION = 0.02, 0.05
"""Range of the chosen height-map cell [m]: seed 000's 5 cm for rooms, 2 cm for a table in view."""

CELLS_ACROSS = 80
"""Cells across the cloud's horizontal extent (square root of its bounding area) at most."""

SPACING_CELLS = 3.0
"""A cell spans at least this many point spacings, so that most cells hold a point."""

LEVEL_DEG = 30.0
"""A plane within this angle of level is a support candidate (as the segmenters' check)."""

FAR_ABOVE = 1.0
"""Level planes whose lowest lies this far above the cloud's low points are not a floor [m]."""


@dataclass(frozen=True)
class PlaneFit:
    """A plane ``normal . p + d = 0`` found by RANSAC.

    Attributes:
        normal: (3,) unit normal.
        d: offset [m].
        inliers: points of the thinned cloud within the inlier distance.
        share: ``inliers`` over all points of the thinned cloud.
    """

    normal: FloatArray
    d: float
    inliers: int
    share: float

    @property
    def tilt_deg(self) -> float:
        """Angle between the normal's line and world z [deg]."""
        return math.degrees(math.acos(min(1.0, abs(float(self.normal[2])))))


SCORE_POINTS = 8000
"""Points on which :func:`dominant_planes` ranks its plane hypotheses."""


def _thin(points: ArrayLike, voxel: float, limit: int, rng: np.random.Generator) -> FloatArray:
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    keys = np.floor(pts / voxel).astype(np.int64)
    if len(keys):  # one int64 per voxel (unique rows sort 100x slower)
        keys -= keys.min(axis=0)
        span = keys.max(axis=0) + 1
        _, first = unique_ints_first((keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2])
        pts = pts[np.sort(first)]
    if len(pts) > limit:
        pts = pts[rng.choice(len(pts), limit, replace=False)]
    return pts


def point_spacing(points: ArrayLike, samples: int = 2000, limit: int = 50_000) -> float:
    """Median distance from a point to its nearest neighbour [m] (points (N, 3) [m]).

    Above ``limit`` points an evenly strided subset is searched and the spacing scaled back by the
    square root of the subsampling factor (surface samples: spacing ~ 1 / sqrt(density)).
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        return 0.0
    stride = max(1, len(pts) // limit)
    sub = pts[::stride]
    tree = cKDTree(sub)
    query = sub[:: max(1, len(sub) // samples)]
    dist, _ = tree.query(query, k=2)
    return float(np.median(dist[:, 1])) / math.sqrt(stride)


def auto_resolution(points: ArrayLike) -> float:
    """The height-map cell for a z-up world cloud (N, 3) [m], from its extent and point spacing.

    ``sqrt(area of the 2-98 % horizontal bounding box) / 80``, at least 3 point spacings, rounded
    up to the centimetre and kept within [0.02, 0.05] m: a 10 m room gets seed 000's 5 cm, a 1.5 m
    table-top view 2 cm.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise InputError("the cloud has no finite points")
    sub = pts[:: max(1, len(pts) // 100_000), :2]
    lo, hi = np.percentile(sub, [2, 98], axis=0)
    extent = math.sqrt(max(float(np.prod(hi - lo)), 0.0))
    spacing = point_spacing(pts)
    raw = max(extent / CELLS_ACROSS, SPACING_CELLS * spacing)
    cell = math.ceil(round(raw * 100, 6)) / 100
    return float(min(MAX_AUTO_RESOLUTION, max(MIN_AUTO_RESOLUTION, cell)))


def dominant_planes(
    points: ArrayLike,
    n_planes: int = 4,
    inlier_dist: float = 0.03,
    rng: np.random.Generator | None = None,
    hypotheses: int = 256,
    min_share: float = 0.03,
) -> list[PlaneFit]:
    """The largest planes of a cloud (N, 3) [m], largest first, by sequential RANSAC.

    The cloud is thinned to one point per 3 cm voxel (at most 40 000); each round draws
    ``hypotheses`` point triples, keeps the plane with most inliers within ``inlier_dist`` [m],
    refits it by least squares and removes its inliers. Planes with less than ``min_share`` of the
    thinned cloud end the search. Normals are not oriented.
    """
    rng = rng or np.random.default_rng(0)
    pts = _thin(points, 0.03, 40_000, rng)
    total = len(pts)
    planes: list[PlaneFit] = []
    while len(planes) < n_planes and len(pts) >= 3:
        tri = pts[rng.integers(0, len(pts), size=(hypotheses, 3))]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(normals, axis=1)
        ok = norm > 1e-9
        if not ok.any():
            break
        normals, tri = normals[ok] / norm[ok, None], tri[ok]
        d = -np.einsum("ij,ij->i", normals, tri[:, 0])
        # scored on an evenly strided subset of at most SCORE_POINTS (preemptive RANSAC: the
        # ranking of 256 hypotheses needs no 40 000 points); the best is refit on all of them
        sub = pts[:: max(1, -(-len(pts) // SCORE_POINTS))]
        counts = np.zeros(len(normals), dtype=np.int64)
        for start in range(0, len(normals), 64):  # bounded memory: 64 x SCORE_POINTS distances at a time
            dist = sub @ normals[start : start + 64].T
            dist += d[start : start + 64]
            np.abs(dist, out=dist)
            counts[start : start + 64] = (dist <= inlier_dist).sum(axis=0)
        best = int(np.argmax(counts))
        inside = np.abs(pts @ normals[best] + d[best]) <= inlier_dist
        if inside.sum() < max(3, min_share * total):
            break
        centroid = pts[inside].mean(axis=0)
        _, _, vt = np.linalg.svd(pts[inside] - centroid, full_matrices=False)
        normal = vt[-1]
        offset = float(-normal @ centroid)
        inside = np.abs(pts @ normal + offset) <= inlier_dist
        planes.append(PlaneFit(normal, offset, int(inside.sum()), float(inside.sum() / total)))
        pts = pts[~inside]
    return planes


def _toward_sensor(plane: PlaneFit) -> FloatArray:
    """The normal oriented toward the sensor at the origin: a camera sees surfaces from their top."""
    return plane.normal if plane.d >= 0 else -plane.normal


def suggest_up(planes: list[PlaneFit], optical: bool, points: FloatArray) -> FloatArray:
    """The likely up vector in the cloud's frame, from its largest planes.

    With ``optical`` (an organized camera cloud: x right, y down, z forward) the largest plane
    whose normal, oriented toward the sensor, lies within 45 deg of -y (the image's up) is taken:
    the floor or a table, not the back wall; a camera sees surfaces from their top. Otherwise the
    largest plane, its normal oriented to the side where most points lie (above a floor).
    """
    if not planes:
        raise InputError("the cloud has no plane to take an up vector from")
    if optical:
        upish = [p for p in planes if -_toward_sensor(p)[1] >= math.cos(math.radians(45))]
        if upish:
            return _toward_sensor(upish[0])
        return _toward_sensor(planes[0])
    n, d = planes[0].normal, planes[0].d
    return n if np.median(points @ n + d) >= 0 else -n


def _fmt(v: ArrayLike) -> str:
    return " ".join(f"{float(x):.4f}" for x in np.asarray(v).ravel())


def check_up_direction(
    points: ArrayLike, optical: bool = False, rng: np.random.Generator | None = None
) -> None:
    """Reject a cloud that is most likely not z-up: raise with the suggested up vector.

    For clouds given without a transform. Flagged: the dominant plane is not level (more than 30 deg
    from it: a wall, or a table seen by a tilted camera) and no level plane holds half as many
    points; or every level plane lies more than 1 m above the cloud's lowest points (the 1st
    percentile of z), so none can be a floor. Ten planes are searched, down to 1 % of the cloud.

    Args:
        points: (N, 3) the cloud as given [m].
        optical: the cloud is an organized camera image (prefer -y as up, see :func:`suggest_up`).
        rng: randomness of RANSAC (default: seed 0).

    Raises:
        InputError: naming the dominant plane and the likely up vector, and how to pass it.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    planes = dominant_planes(pts, n_planes=10, min_share=0.01, rng=rng)
    if not planes:
        return
    level = [p for p in planes if p.tilt_deg <= LEVEL_DEG]
    dominant = planes[0]
    why = None
    if dominant.tilt_deg > LEVEL_DEG and not any(p.inliers >= 0.5 * dominant.inliers for p in level):
        why = f"its dominant plane is {dominant.tilt_deg:.0f} deg from level, and no level plane is half as large"
    elif level:
        low = float(np.percentile(pts[:, 2], 1))
        heights = [-p.d / p.normal[2] for p in level]
        if min(heights) - low > FAR_ABOVE:
            why = (f"its level planes lie {min(heights) - low:.1f} m or more above its lowest points "
                   "(a wall seen from a camera, not a floor)")  # fmt: skip
    if why is None:
        return
    up = suggest_up(planes, optical, pts)
    raise InputError(
        f"the cloud does not look z-up: {why}; the likely up vector in its frame is ({_fmt(up)}): "
        f'pass --transform "{_fmt(up)}" (or a 4x4 world_T_sensor file, or --transform "0 0 1" if it is z-up)'
    )


def explain_no_support(points: ArrayLike, resolution: float, rng: np.random.Generator | None = None) -> str:
    """Why a z-up cloud (N, 3) [m] gave no support region at ``resolution`` [m]: a one-line message.

    If RANSAC finds a level plane, it was too small for the cell: the message names its area and a
    finer resolution to try (half the cell, at most 2 cm, at least 1.2 point spacings). Otherwise it names the dominant plane's normal as the up vector to pass.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    planes = dominant_planes(pts, n_planes=10, min_share=0.01, rng=rng)
    level = [p for p in planes if p.tilt_deg <= LEVEL_DEG]
    if level:
        best = level[0]
        inside = np.abs(pts @ best.normal + best.d) <= 0.03
        xy = pts[inside, :2]
        area = _occupied_area(xy, 0.02) if len(xy) else 0.0
        # finer, but not below the points' own spacing (a fused OctoMap is a 25 mm lattice)
        floor = math.ceil(round(1.2 * point_spacing(pts) * 100, 6)) / 100
        finer = max(0.01, min(resolution / 2, 0.02), floor)
        return (
            f"no planar region large enough at --resolution {resolution:g} m: the largest level plane "
            f"(z = {float(np.median(pts[inside, 2])):.2f} m, about {area:.2f} m^2) is too small for "
            f"this cell size; try --resolution {finer:g}"
        )
    if not planes:
        return "no horizontal support surface found, and no plane in the cloud at all"
    up = planes[0].normal
    return (
        f"no horizontal support surface found: no plane within {LEVEL_DEG:.0f} deg of level (is the "
        f"cloud's up direction right?); the dominant plane's normal is ({_fmt(up)}) (or its "
        f'opposite): if that is up, pass it as the up vector, --transform "{_fmt(up)}"'
    )


def _occupied_area(xy: FloatArray, cell: float) -> float:
    keys = np.unique(np.floor(xy / cell).astype(np.int64), axis=0)
    return float(len(keys) * cell * cell)
