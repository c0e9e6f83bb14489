"""Neighbour objects near the grasped object as fitted whole shapes: upright cylinders and boxes (issue 25).

A raw point at a neighbour bottle's rim keeps the whole clearance c (its own error is the noise,
u = n: :mod:`baseplace.world.sensor_resolution`), and local two-face fits of 8-20 points did not do
better (session 14). A whole neighbour holds hundreds of points: a shape fitted to all of them knows
where its surface lies to about sigma / sqrt(N), far below one point's noise, if the neighbour IS
that shape. Here the points near the object that are neither the object's nor the support plane's
are split into clusters (connected at :data:`LINK`, :func:`clusters`), and each standing on the
support plane is fitted (:func:`fit_cluster`) by an upright cylinder (axis along the plane's normal:
a circle fitted to its side points in plane coordinates, Gauss-Newton on the geometric distance; the
top from the points around its highest layer; the bottom on the plane) and by a box (its footprint's
minimum-area rectangle, each face's offset fitted to that face's points). A fit is accepted
(:func:`accepted`) only when the cluster fits it:

* coverage: the side points fill every one of :data:`SECTORS` angular sectors around the axis (a
  box: every face) with at least :data:`PATCH_POINTS` points each, the side spans the height to
  within :data:`RIM_BAND` of the plane and the top, and the top layer holds at least
  :data:`PATCH_POINTS` points. A cloud that sees one side of a neighbour only is not fitted;
* every point lies at most :data:`POINT_SIGMAS` sigma outside each face of the fitted surface (inside is free:
  the fitted solid covers it): a mug's handle, a box's corners beyond a cylinder, a cluster of two
  touching objects leave points outside and reject the fit;
* no point lies over the footprint shrunk by :data:`POINT_SIGMAS` sigma lower than that under the
  top: a prism shows nothing there (a bottle's neck, a mug's open top and inner wall do);
* each patch of the surface (the side cut in :data:`SECTORS` sectors and bands :data:`PATCH` high,
  the top in one; and again in rings :data:`RING` high all around and in strips :data:`STRIP` wide
  over its height; those of at least :data:`PATCH_POINTS` points) has its points' mean outward
  distance at most tau = :data:`~baseplace.world.sensor_resolution.CLEARANCE_SIGMAS` sigma /
  sqrt(k) (k its points): a deviation of the true surface broad enough to move a patch's mean.

A fit's u (below) may exceed n, the raw points' own: a 10 cm box's is 10.5 mm at n = 9 mm (its
corners from a footprint angle that is not refined). It is taken all the same: an exact solid has
no gaps between samples, where a sparse cloud's raw cells let spheres through at edges and rims
(tests/test_clearance_bound_spacing.py: its eight known holes close on the fitted neighbours; the
box at 9 and 12.5 mm spacing needs u >= n for that).

The fitted shape's own error u (:attr:`FittedShape.error`) is then 3 standard errors of the fit
(the least-squares covariance: the radius and the centre's worst direction, the top's height; a
box's face offsets and its angle at the corners) plus 2 tau_max: a patch that deviates outward by D
passes with a mean D + e <= tau, and D <= tau + 3 sigma / sqrt(k) = 2 tau at 3 sigma of e. Features
smaller than a patch in both directions (not a ring, not a strip) and less than
:data:`POINT_SIGMAS` sigma proud (a bump of a few samples) pass every test:
the fit assumes the neighbour is the primitive up to those; that is its limit, and there the
clearance bound does not hold. The side is therefore also cut in :data:`TILE` square tiles (four
offset grids), each tested at :data:`TILE_SIGMAS` (not in u). Measured at 3 mm noise on a 4 cm,
20 cm tall bottle with a 2 cm square bump on its side (bench/shape_fits.py, the fit alone, 10 draws):
6 mm proud accepted in 6 (9 without the tiles), the true bump up to 2 mm beyond u; 10 mm proud in 0
(1 without). Through the whole scene model a 5 mm bump passed in 1 of 10 draws, 0.7 mm beyond u
(tests/test_neighbour_shapes.py, a strict expected failure until it is closed). A clearance given
above the derived one (``--clearance``) covers such a feature by its excess.

The accepted neighbour becomes an exact convex prism (:meth:`FittedShape.geometry`: the cylinder's
circumscribed :data:`SEGMENTS`-gon, the box itself) kept at c - n + u (:func:`~baseplace.world.sensor_resolution.margin`),
and its points leave the fine cells; a rejected cluster stays as it was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import coal
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from baseplace.geometry.poses import FloatArray
from baseplace.world.support_plane import CLEARANCE_SIGMAS, SupportSlab

LINK = 0.02
"""Points closer than this [m] belong to one cluster: twice the 1 cm sampling of a neighbour."""
MIN_POINTS = 60
"""A cluster of fewer points is not fitted."""
RIM_BAND = 0.015
"""Side points lie this far [m] below the top layer and above the plane at least (the rim's and
the foot's points belong to both faces)."""
SECTORS = 6
"""A cylinder's side is cut in this many angular sectors, each to be covered (:func:`accepted`)."""
TOP_INSET = 0.005
"""The top is fitted to the points over the footprint shrunk by this [m] (:func:`_top`)."""
PATCH = 0.08
"""A side patch is about this high [m] (the side cut evenly)."""
RING = 0.02
"""The side is also cut in rings this high [m] all around: a band proud of the side (a label, a lid's
rim) narrower than :data:`PATCH` moves a ring's mean (:func:`accepted`)."""
STRIP = 0.02
"""And in strips this wide [m] over its whole height: a ridge narrower than a sector."""
TILE = 0.02
"""The side is also cut in square tiles this wide [m], on four grids offset by half a tile (:func:`accepted`)."""
TILE_POINTS = 4
"""Tiles of fewer points are not tested."""
TILE_SIGMAS = 4.0
"""A tile's mean outward residual above this many sigma / sqrt(k) rejects the fit: a small proud feature
(bench/shape_fits.py: a 2 cm bump 10 mm proud of a 4 cm bottle accepted in 0 of 30 draws instead of 4, 6 mm
proud in 11 instead of 25; the true 3-4.5 cm bottles lost none of 90 draws). Not in u: it lowers the chance
that such a feature passes, it does not bound it."""
PATCH_POINTS = 9
"""Each sector (box: face) and the top hold at least this many points; patches of fewer are not tested."""
POINT_SIGMAS = 4.5
"""No point of an accepted cluster lies more than this many sigma outside a face of the fitted
surface: once in 290 000 points' residuals. A neighbour has a few hundred points, an edge's points
two residuals each, a corner's three: at 4 sigma (once in 30 000) a true 10 cm box was rejected in
one of three draws of tests/test_clearance_bound.py (a point 13.1 mm out, 4 sigma 12.2 mm)."""
SEGMENTS = 32
"""The cylinder's prism is its circumscribed regular polygon of this many sides (its corners lie
r (1 / cos(pi / SEGMENTS) - 1) outside it: 0.2 mm on a 4 cm bottle)."""


@dataclass(frozen=True)
class FittedShape:
    """A neighbour object fitted as an upright cylinder or box (world frame).

    Attributes:
        kind: "cylinder" or "box".
        origin: (3,) a point on the support plane [m], the origin of ``axes``.
        axes: (3, 3) columns: two directions along the plane and its upward normal.
        centre: (2,) the axis (cylinder) or the footprint's centre (box) in plane coordinates [m].
        size: (radius,) or (half length, half width) [m], the box along ``angle`` and across.
        angle: the box's first side's direction [rad] in plane coordinates (0 for a cylinder).
        height: the top above the plane [m].
        error: u [m], the fit's own error at 3 sigma plus the acceptance's allowance (module docstring).
        noise_margin: the scene's noise margin n [m].
        points: how many points it replaces.
    """

    kind: str
    origin: FloatArray
    axes: FloatArray
    centre: FloatArray
    size: tuple[float, ...]
    angle: float
    height: float
    error: float
    noise_margin: float
    points: int

    def footprint(self) -> FloatArray:
        """(K, 2) the prism's footprint polygon in plane coordinates, counter-clockwise [m]."""
        if self.kind == "cylinder":
            r = self.size[0] / math.cos(math.pi / SEGMENTS)
            a = np.linspace(0.0, 2 * math.pi, SEGMENTS, endpoint=False)
            return self.centre + r * np.c_[np.cos(a), np.sin(a)]
        c, s = math.cos(self.angle), math.sin(self.angle)
        u, v = np.array([c, s]) * self.size[0], np.array([-s, c]) * self.size[1]
        return self.centre + np.array([u + v, -u + v, -u - v, u - v])

    def vertices(self) -> FloatArray:
        """(2K, 3) the prism's corners in the world frame [m]: its footprint on the plane and at its top."""
        f = self.footprint()
        local = np.concatenate([np.c_[f, np.zeros(len(f))], np.c_[f, np.full(len(f), self.height)]])
        return np.asarray(self.origin + local @ self.axes.T, dtype=float)

    def geometry(self) -> coal.Convex:
        """The prism as a coal convex (world frame)."""
        vertices = coal.StdVec_Vec3s()
        for v in self.vertices():
            vertices.append(np.asarray(v, dtype=float))
        return coal.Convex.convexHull(vertices, False, "")

    def signed_distance(self, points: ArrayLike) -> FloatArray:
        """(N,) each point's distance [m] to the fitted solid (not the polygon), negative inside."""
        L = (np.asarray(points, dtype=float).reshape(-1, 3) - self.origin) @ self.axes
        return _signed(self, L)

    def __len__(self) -> int:
        return 1


def plane_frame(slab: SupportSlab) -> tuple[FloatArray, FloatArray]:
    """(origin (3,), axes (3, 3)) of the support plane: a point on it and columns along it and up its normal."""
    a, b, c = slab.coeffs
    normal = np.array([-a, -b, 1.0]) / math.sqrt(a * a + b * b + 1.0)
    e1 = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    e1 /= np.linalg.norm(e1)
    return np.array([0.0, 0.0, c]), np.c_[e1, np.cross(normal, e1), normal]


def clusters(points: ArrayLike, link: float = LINK) -> NDArray[np.int64]:
    """(N,) the connected component of each point (N, 3) [m], points closer than ``link`` joined."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(p).query_pairs(link, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(p), len(p)))
    return np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)


def fit_neighbours(
    points: ArrayLike, slab: SupportSlab, noise_margin: float
) -> list[tuple[FittedShape, NDArray[np.int64]]]:
    """The accepted fits of the clusters of ``points`` (N, 3) [m], each with its points' indices.

    Per cluster of at least :data:`MIN_POINTS` standing on the plane (no point more than
    :data:`POINT_SIGMAS` sigma below it), the cylinder and the box (:func:`fit_cluster`); of those
    :func:`accepted`, the one of smaller error.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    origin, axes = plane_frame(slab)
    sigma = _sigma(noise_margin)
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


def fit_cluster(
    L: FloatArray, origin: FloatArray, axes: FloatArray, noise_margin: float
) -> list[FittedShape]:
    """The cylinder and the box fitted to a cluster's points ``L`` (N, 3) in plane coordinates [m].

    The side from the points between :data:`RIM_BAND` above the plane and below the highest layer
    (:func:`_circle`, :func:`_box`); the top from the points over the footprint shrunk by
    :data:`TOP_INSET` within 3 sigma of its layer (:func:`_top`: a side's last row below the rim
    would pull it down). Their :attr:`~FittedShape.error` holds the fit's 3 standard errors only;
    :func:`accepted` adds its allowance. None that cannot be fitted (too few side or top points).
    """
    sigma = _sigma(noise_margin)
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


def accepted(shape: FittedShape, L: FloatArray) -> FittedShape | None:
    """The fit with the acceptance's allowance in its error, or None when the cluster does not fit it.

    ``L`` (N, 3) the cluster's points in plane coordinates: the coverage, point and patch rules of
    the module docstring.

    A patch's residuals are along its own face (radial or across the box's face on the side, height
    on the top): the distance to the solid is biased outward near its edges, where noise either way
    counts as outside.
    """
    sigma = _sigma(shape.noise_margin)
    if _signed(shape, L, euclidean=False).max() > POINT_SIGMAS * sigma:
        return None
    deep = _inner(shape, L, POINT_SIGMAS * sigma)  # a prism shows nothing under its top but its top
    if np.any(L[deep, 2] < shape.height - POINT_SIGMAS * sigma):
        return None
    patches = _patches(shape, L)
    if patches is None:
        return None
    cuts, residual, tiles = patches
    for tile in tiles:  # small features: tested, not in u (TILE_SIGMAS)
        k = np.bincount(tile[tile >= 0])
        total = np.bincount(tile[tile >= 0], weights=residual[tile >= 0])
        tested = k >= TILE_POINTS
        if np.any(total[tested] / k[tested] > TILE_SIGMAS * sigma / np.sqrt(k[tested])):
            return None
    tau_max = 0.0
    for patch in cuts:
        for k in np.unique(patch[patch >= 0]):
            mine = patch == k
            if mine.sum() >= PATCH_POINTS:
                tau = 3 * sigma / math.sqrt(mine.sum())
                if residual[mine].mean() > tau:
                    return None
                tau_max = max(tau_max, tau)
    return replace(shape, error=shape.error + 2 * tau_max)


def _sigma(noise_margin: float) -> float:
    return noise_margin / CLEARANCE_SIGMAS


def _top(shape: FittedShape, L: FloatArray, rough: float, sigma: float) -> tuple[float, int] | None:
    """The top's height [m] and its points' count, or None (fewer than :data:`PATCH_POINTS`).

    The mean height of the points over the footprint shrunk by :data:`TOP_INSET` within 3 sigma of
    the layer, started at ``rough`` (the 98th percentile) and iterated.
    """
    inner = _inner(shape, L, TOP_INSET)
    top = rough
    for _ in range(4):
        near = inner & (np.abs(L[:, 2] - top) <= 3 * sigma)
        if near.sum() < PATCH_POINTS:
            return None
        top = float(L[near, 2].mean())
    return top, int(near.sum())


def _box_frame(shape: FittedShape, L: FloatArray) -> FloatArray:
    """(N, 2) the points ``L`` (plane coordinates) along a box's first side and across it, from its centre [m]."""
    c, s = math.cos(shape.angle), math.sin(shape.angle)
    v = L[:, :2] - shape.centre
    return np.c_[v @ [c, s], v @ [-s, c]]


def _inner(shape: FittedShape, L: FloatArray, inset: float) -> NDArray[np.bool_]:
    """(N,) the points ``L`` (plane coordinates) over the footprint shrunk by ``inset`` [m]."""
    if shape.kind == "cylinder":
        v = L[:, :2] - shape.centre
        return np.asarray(np.hypot(v[:, 0], v[:, 1]) <= shape.size[0] - inset)
    return np.asarray(np.all(np.abs(_box_frame(shape, L)) <= np.asarray(shape.size) - inset, axis=1))


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
            best = (area, a)
    assert best is not None
    a = best[1]
    R = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
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


def _signed(shape: FittedShape, L: FloatArray, euclidean: bool = True) -> FloatArray:
    """(N,) the signed distance [m] of points ``L`` (N, 3, plane coordinates) to the fitted solid.

    ``euclidean`` False: the largest distance outside one of its faces' planes (side, top, bottom), not
    the distance to an edge, which noise outward across both faces lengthens (by sqrt(2) at 45 deg).
    """
    t = L[:, 2]
    axial = np.maximum(t - shape.height, -t)  # the bottom on the plane
    if shape.kind == "cylinder":
        radial = np.hypot(L[:, 0] - shape.centre[0], L[:, 1] - shape.centre[1]) - shape.size[0]
        out = np.c_[radial, axial]
    else:
        q = np.abs(_box_frame(shape, L)) - shape.size
        out = np.c_[q, axial]
    if not euclidean:
        return np.asarray(out.max(axis=1), dtype=float)
    outside = np.linalg.norm(np.maximum(out, 0.0), axis=1)
    return np.asarray(outside + np.minimum(out.max(axis=1), 0.0), dtype=float)


def _patches(
    shape: FittedShape, L: FloatArray
) -> tuple[list[NDArray[np.int64]], FloatArray, list[NDArray[np.int64]]] | None:
    """Three cuts into patches ((N,) each point's, -1: none), (N,) outward residuals [m], the side's tiles.

    The tiles: :data:`TILE` square, on four offset grids, each an (N,) cut like the others. None: no coverage.

    Each residual is along the point's own face.

    Side (the points between :data:`RIM_BAND` above the plane and below the top): the sector
    (cylinder: :data:`SECTORS` around its axis; box: its face) times the side's height cut evenly in
    bands of about :data:`PATCH`;
    top: one patch (the points over the footprint shrunk by :data:`TOP_INSET`, within
    :data:`RIM_BAND` of its height). Rings: the side cut in slices :data:`RING` high all around.
    Strips: the side cut in columns :data:`STRIP` wide over its whole height.
    Coverage: every sector or face holds :data:`PATCH_POINTS` side points, the side points reach within :data:`RIM_BAND` + :data:`PATCH` of the plane and of the
    top, the top holds :data:`PATCH_POINTS`.
    """
    t = L[:, 2]
    side = (t > RIM_BAND) & (t < shape.height - RIM_BAND)
    top = _inner(shape, L, TOP_INSET) & (np.abs(t - shape.height) <= RIM_BAND)
    v = L[:, :2] - shape.centre
    if shape.kind == "cylinder":
        angle = np.arctan2(v[:, 1], v[:, 0])
        sector = np.minimum(
            np.floor((angle + math.pi) / (2 * math.pi) * SECTORS).astype(np.int64), SECTORS - 1
        )
        count = SECTORS
        residual = np.hypot(v[:, 0], v[:, 1]) - shape.size[0]
        along = angle * shape.size[0]
        strips_around = max(1, round(2 * math.pi * shape.size[0] / STRIP))
        strip = np.minimum(np.floor((angle + math.pi) / (2 * math.pi) * strips_around), strips_around - 1)
    else:
        q = _box_frame(shape, L)
        scaled = q / np.asarray(shape.size)
        along_first = np.abs(scaled[:, 0]) >= np.abs(scaled[:, 1])
        face = np.where(along_first, np.where(q[:, 0] > 0, 0, 1), np.where(q[:, 1] > 0, 2, 3))
        sector, count = face.astype(np.int64), 4
        residual = np.where(along_first, np.abs(q[:, 0]) - shape.size[0], np.abs(q[:, 1]) - shape.size[1])
        width = np.where(along_first, 2 * shape.size[1], 2 * shape.size[0])  # each face cut evenly
        across = np.where(along_first, q[:, 1] + shape.size[1], q[:, 0] + shape.size[0]) / width
        along = face * 10.0 + across * width  # [m] along each face, the faces far apart
        per_face = np.maximum(np.round(width / STRIP), 1)
        strip = face * 1000 + np.clip(np.floor(across * per_face), 0, per_face - 1)
    residual = np.where(top, t - shape.height, residual)
    if np.bincount(sector[side], minlength=count).min() < PATCH_POINTS or top.sum() < PATCH_POINTS:
        return None
    ts = t[side]
    if ts.min() > RIM_BAND + PATCH or ts.max() < shape.height - RIM_BAND - PATCH:
        return None
    span = shape.height - 2 * RIM_BAND  # the side cut evenly: no sliver of a band at its top
    bands = max(1, round(span / PATCH))
    band = np.clip(np.floor((t - RIM_BAND) / span * bands), 0, bands - 1).astype(np.int64)
    rings = max(1, round(span / RING))
    ring = np.clip(np.floor((t - RIM_BAND) / span * rings), 0, rings - 1).astype(np.int64)
    patches = np.full(len(L), -1, dtype=np.int64)
    patches[side] = sector[side] * bands + band[side]
    patches[top] = count * bands
    around = np.full(len(L), -1, dtype=np.int64)
    around[side] = ring[side]
    strips = np.full(len(L), -1, dtype=np.int64)
    strips[side] = strip[side]
    tiles = []
    for shift in (
        (0.0, 0.0),
        (0.5, 0.0),
        (0.0, 0.5),
        (0.5, 0.5),
    ):  # four grids: a feature across a tile's edge
        key = np.floor(along / TILE + shift[0]) * 1e4 + np.floor(t / TILE + shift[1])
        tile = np.full(len(L), -1, dtype=np.int64)
        tile[side] = np.unique(key[side], return_inverse=True)[1]
        tiles.append(tile)
    return [patches, around, strips], np.asarray(residual, dtype=float), tiles
