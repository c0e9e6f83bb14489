"""One cluster of neighbour points fitted as an upright cylinder and as a box (issue 25).

The points are in the support plane's coordinates (z up its normal). The cylinder: a circle fitted
to its side points, Kasa's algebraic fit then Gauss-Newton on the geometric distance (:func:`_circle`);
the box: its footprint's minimum-area rectangle, each face's offset fitted to that face's points
(:func:`_box`); both: the top from the points around its highest layer (:func:`_top`), the bottom on
the plane. Each fit's :attr:`~baseplace.world.fitted_shape.FittedShape.error` is 3 standard errors of
the fit (the least-squares covariance: the radius and the centre's worst direction, the top's height;
a box's face offsets and its angle at the corners); the acceptance test
(:mod:`~baseplace.world.fit_acceptance`) adds its allowance. The method and its limits:
:mod:`baseplace.world.neighbour_shapes`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from baseplace.geometry.poses import FloatArray
from baseplace.world.fitted_shape import FittedShape, noise_sigma

RIM_BAND = 0.015
"""Side points lie this far [m] below the top layer and above the plane at least (the rim's and
the foot's points belong to both faces)."""
TOP_INSET = 0.005
"""The top is fitted to the points over the footprint shrunk by this [m] (:func:`_top`)."""
PATCH_POINTS = 9
"""Each sector (box: face) and the top hold at least this many points; patches of fewer are not tested
(:func:`~baseplace.world.fit_acceptance.accepted`)."""


def fit_cluster(
    L: FloatArray, origin: FloatArray, axes: FloatArray, noise_margin: float
) -> list[FittedShape]:
    """The cylinder and the box fitted to a cluster's points ``L`` (N, 3) in plane coordinates [m].

    The side from the points between :data:`RIM_BAND` above the plane and below the highest layer
    (:func:`_circle`, :func:`_box`); the top from the points over the footprint shrunk by
    :data:`TOP_INSET` within 3 sigma of its layer (:func:`_top`: a side's last row below the rim
    would pull it down). Their :attr:`~FittedShape.error` holds the fit's 3 standard errors only;
    :func:`~baseplace.world.fit_acceptance.accepted` adds its allowance. None that cannot be fitted
    (too few side or top points).
    """
    sigma = noise_sigma(noise_margin)
    rough = float(np.quantile(L[:, 2], 0.98))
    side = L[(L[:, 2] > RIM_BAND) & (L[:, 2] < rough - RIM_BAND), :2]
    if len(side) < 2 * PATCH_POINTS:
        return []
    out = []
    circle = _circle(side, sigma)
    if circle is not None:
        centre, r, error = circle
        out.append(
            FittedShape("cylinder", origin, axes, centre, (r,), 0.0, rough, error, noise_margin, len(L))
        )
    box = _box(side, sigma)
    if box is not None:
        centre, half, angle, error = box
        out.append(FittedShape("box", origin, axes, centre, half, angle, rough, error, noise_margin, len(L)))
    topped = []
    for shape in out:
        top = _top(shape, L, rough, sigma)
        if top is not None:
            height, count = top
            error = max(shape.error, 3 * sigma / math.sqrt(count))
            topped.append(replace(shape, height=height, error=error))
    return topped


def _top(shape: FittedShape, L: FloatArray, rough: float, sigma: float) -> tuple[float, int] | None:
    """The top's height [m] and its points' count, or None (fewer than :data:`PATCH_POINTS`).

    The mean height of the points over the footprint shrunk by :data:`TOP_INSET` within 3 sigma of
    the layer, started at ``rough`` (the 98th percentile) and iterated.
    """
    inner = shape.over_footprint(L, TOP_INSET)
    top = rough
    for _ in range(4):
        near = inner & (np.abs(L[:, 2] - top) <= 3 * sigma)
        if near.sum() < PATCH_POINTS:
            return None
        top = float(L[near, 2].mean())
    return top, int(near.sum())


def _circle(xy: FloatArray, sigma: float) -> tuple[FloatArray, float, float] | None:
    """(centre (2,), radius, 3 standard errors of the outward surface [m]) of a circle fitted to ``xy``.

    Kasa's algebraic fit, then Gauss-Newton on the geometric distance; the covariance from the
    residuals (at least sigma) and the Jacobian: the radius plus the centre's worst direction.
    """
    A = np.c_[2 * xy, np.ones(len(xy))]
    sol, *_ = np.linalg.lstsq(A, (xy**2).sum(axis=1), rcond=None)
    c, r = sol[:2], math.sqrt(max(sol[2] + sol[:2] @ sol[:2], 0.0))
    for _ in range(10):
        v = xy - c
        rho = np.linalg.norm(v, axis=1)
        if np.any(rho < 1e-9):
            return None
        J = np.c_[-v / rho[:, None], -np.ones(len(xy))]
        step, *_ = np.linalg.lstsq(J, -(rho - r), rcond=None)
        c, r = c + step[:2], r + step[2]
    v = xy - c
    rho = np.linalg.norm(v, axis=1)
    res = rho - r
    J = np.c_[-v / rho[:, None], -np.ones(len(xy))]
    s2 = max(float(res @ res) / max(len(xy) - 3, 1), sigma * sigma)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    worst = cov[2, 2] + float(np.linalg.eigvalsh(cov[:2, :2]).max()) + 2 * float(np.linalg.norm(cov[2, :2]))
    if not (0 < r < 1.0) or not np.isfinite(worst):
        return None
    return c, float(r), 3 * math.sqrt(worst)


def _box(xy: FloatArray, sigma: float) -> tuple[FloatArray, tuple[float, float], float, float] | None:
    """(centre (2,), half sides, angle [rad], 3 standard errors [m]) of a rectangle fitted to ``xy``.

    The angle from the minimum-area rectangle of their hull, then each face's offset from the points
    nearest it (away from the corners by :data:`RIM_BAND`), its slope giving the angle's error (at a
    corner, half the side times it).
    """
    try:
        hull = xy[ConvexHull(xy).vertices]
    except (QhullError, ValueError):
        return None
    best = None
    for k in range(len(hull)):
        e = hull[(k + 1) % len(hull)] - hull[k]
        a = math.atan2(e[1], e[0])
        R = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        q = hull @ R.T
        area = float(np.ptp(q[:, 0]) * np.ptp(q[:, 1]))
        if best is None or area < best[0]:
            best = (area, a, R)
    assert best is not None
    _, a, R = best
    q = xy @ R.T
    mid = (q.min(axis=0) + q.max(axis=0)) / 2
    q = q - mid
    half0 = (q.max(axis=0) - q.min(axis=0)) / 2
    faces, errors, slopes = [], [], []
    for axis in (0, 1):
        other = 1 - axis
        for sign in (1.0, -1.0):
            mine = (sign * q[:, axis] > half0[axis] / 2) & (np.abs(q[:, other]) < half0[other] - RIM_BAND)
            mine &= sign * q[:, axis] - half0[axis] > np.abs(q[:, other]) - half0[other]
            if mine.sum() < PATCH_POINTS:
                return None
            w, s = q[mine, axis], q[mine, other]
            faces.append(float(w.mean()))
            errors.append(sigma / math.sqrt(mine.sum()))
            spread = float(((s - s.mean()) ** 2).sum())
            slopes.append(sigma / math.sqrt(max(spread, 1e-12)))
    lo = np.array([faces[1], faces[3]])
    hi = np.array([faces[0], faces[2]])
    half = (hi - lo) / 2
    if np.any(half <= 0):
        return None
    centre = mid + (hi + lo) / 2
    corner = float(np.hypot(*half)) * max(slopes)
    error = 3 * (max(errors) + corner)
    return centre @ R, (float(half[0]), float(half[1])), a, error
