"""The scene near the grasped object at sensor resolution, its support an exact plane (issue 25).

A 25 mm voxel over-approximates its points by up to a whole cube, so the hand working a few
centimetres from a table top or a neighbour met voxels while the true scene was free. Within
:data:`~baseplace.world.support_plane.RADIUS` of the object's footprint (the hand's approach plus
its length) the support and obstacle groups are the cloud's own points in :data:`FINE` cells
instead (:func:`fine_groups`); farther away the 25 mm voxels stay. The plane the object stands on,
when the cloud fits one (:func:`~baseplace.world.support_plane.fit_support_slab`), is an exact
plane (:class:`SupportPlane`): a prism whose top face is the fitted plane, and its points leave
the point groups. The robot keeps :attr:`~baseplace.world.environment.Environment.clearance` from
the fine cells and the plane, derived from the plane's noise (:func:`derived_clearance`).

The noise is counted once. A noisy point lies up to about 3 sigma outside the true surface; kept
as measured in its 5 mm cell, the clearance stood on top of that noise and of the cell (measured on
bench/find_rate.py's dev scenes, 3 mm noise: cells up to 11-15 mm outside the true bottles, so the
margin from a bottle was the clearance plus 5 mm (median) to 12 mm, while the exact plane stood at
the clearance). So each point is first put onto the plane fitted to its neighbours, an edge's
points onto the faces' planes (:func:`denoised`), and the cells are :data:`FINE` = 1.25 mm. A
denoised point may lie a little inside a curved surface (the plane is a chord of it), and a small
link may come between points 1 cm apart: the point cells keep the clearance plus
:data:`SURFACE_ALLOWANCE` (:func:`margin`). The margin from the true surface, measured with
5 mm spheres all around a noisy 3.5 cm bottle (tests/test_clearance_from_true_surface.py's scene,
three noise draws, 510 probes): the clearance plus 0.0 to 5.5 mm, median 2.6 mm (before: plus
0.2 to 12.4 mm, median 5.3 mm, and then 0.9 clearances from the side were free between points).
That test checks it with coal on the true cylinder: 0.9 clearances refused everywhere, a 4 cm
cube 1.75 clearances away free everywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.grasped_object import GraspedObject, rows_in
from baseplace.world.support_plane import DEPTH, RADIUS, SUPPORT_PLANE, SupportSlab

FINE = 0.00125
"""Cell edge [m] of the points near the object (each put onto its local plane first, :func:`denoised`):
a cell reaches 0 to FINE beyond its point along each axis."""
MAX_FINE = 0.005
"""Cells no coarser than this [m] are at sensor resolution and kept at the clearance: the :data:`FINE`
cells here and the experiments' 5 mm slab cells (:func:`~baseplace.world.support_plane.with_support_slab`)."""
SURFACE_ALLOWANCE = 0.004
"""Added [m] to the clearance kept from the point cells (not from the exact plane): how much closer
than the true surface their cells may let a link come. Measured with the allowance 0
(tests/test_clearance_from_true_surface.py's scene, 3 mm noise, points 1 cm apart, a 3.5 cm bottle;
spheres of 5 mm radius): 4.0 mm at most, from the local plane's chord under a curved surface (about
rho^2 / (8 r): 2.2 mm there), the gaps between the points and the plane's own error (sigma / 4)."""
PLANE_DEPTH = 0.05
"""The exact plane is a prism this thick [m] under its top face."""
OBJECT_TOLERANCE = 0.0125
"""Points this close [m] to a given box or cylinder are the object's (4 sigma of 3 mm sensor noise)."""
CLEARANCE_SIGMAS = 3.0
"""The derived clearance is this many robust standard deviations of the support plane's residuals."""
MIN_CLEARANCE = 0.003
"""The derived clearance is at least this [m]: a sensor's quantisation and calibration error."""
DEFAULT_CLEARANCE = 0.01
"""The clearance [m] when no noise can be measured (too few points near the object): 3 sigma of 3 mm
noise, rounded up."""
NOISE_NEIGHBOURS = 16
"""Each local plane of :func:`surface_noise` is fitted to a point's this many nearest neighbours."""
NOISE_QUANTILE = 0.2
"""The share of local fits read (:func:`surface_noise`): at least this many neighbourhoods must be flat."""
NOISE_SAMPLES = 4000
"""At most this many points (every n-th) have their local plane fitted."""
MAX_CLEARANCE = 0.1
"""The largest clearance [m] accepted: more would forbid most grasps outright."""
PLANAR_FACTOR = 1.5
"""A point is moved onto its local plane (:func:`denoised`) when that plane's fit is no worse than
this many times the surfaces' noise; above it (an edge, a corner) the point goes onto a neighbour's plane."""
MAX_MOVE_SIGMAS = 3.0
""":func:`denoised` moves a point at an edge by at most this many times the surfaces' noise (a larger
offset is shape, not noise): no corner is rounded inward by more than that, about the derived clearance."""


@dataclass(frozen=True)
class SupportPlane:
    """The surface the grasped object stands on as an exact plane (world frame).

    Attributes:
        slab: the fit (plane z = a x + b y + c, its residuals' sigma).
        hull: (H, 2) counter-clockwise footprint [m] of the points the plane replaces.
        points: how many points it replaces.
    """

    slab: SupportSlab
    hull: FloatArray
    points: int

    def geometry(self) -> coal.Convex:
        """A coal prism over :attr:`hull`: top face on the plane, :data:`PLANE_DEPTH` thick (world frame)."""
        top = np.c_[self.hull, self.slab.height(self.hull)]
        vertices = coal.StdVec_Vec3s()
        for v in np.concatenate([top, top - [0.0, 0.0, PLANE_DEPTH]]):
            vertices.append(np.asarray(v, dtype=float))
        return coal.Convex.convexHull(vertices, False, "")

    def __len__(self) -> int:
        return 1


Group = VoxelMap | SupportPlane | tuple[VoxelMap, ...]
"""An obstacle group of :class:`~baseplace.world.environment.Environment`: voxels or cells of one
resolution, the exact support plane, or several of those parts (coarse far away, fine near)."""


def group_parts(group: Group) -> tuple[VoxelMap | SupportPlane, ...]:
    """The parts of a group, each one collision geometry."""
    return group if isinstance(group, tuple) else (group,)


def group_size(group: Group) -> int:
    """How many cells (or planes) a group holds."""
    return sum(len(p) for p in group_parts(group))


def margin(part: VoxelMap | SupportPlane, clearance: float) -> float:
    """The distance [m] below which a link touches ``part`` (coal's security margin).

    The clearance plus :data:`SURFACE_ALLOWANCE` from the (denoised) point cells, the clearance from
    the exact plane and other cells of at most :data:`MAX_FINE`, nothing from coarser voxels.
    """
    if isinstance(part, VoxelMap) and part.resolution <= FINE + 1e-12:
        return clearance + SURFACE_ALLOWANCE
    return clearance if is_fine(part) else 0.0


def is_fine(part: VoxelMap | SupportPlane) -> bool:
    """True for the parts the clearance applies to: the exact plane and cells no coarser than :data:`MAX_FINE`."""
    return isinstance(part, SupportPlane) or part.resolution <= MAX_FINE + 1e-12


def surface_noise(points: ArrayLike) -> tuple[float, int] | None:
    """The sensor noise [m] of a cloud's surfaces (N, 3) and how many local fits measured it, or None.

    Without a support plane to fit, the noise is read off the surfaces themselves: at up to
    :data:`NOISE_SAMPLES` points, the plane through its :data:`NOISE_NEIGHBOURS` nearest
    neighbours (the covariance's smallest eigenvalue over k - 3 degrees of freedom). On a flat
    surface each such standard deviation is sigma times a chi variable of k - 3 degrees of
    freedom; edges, corners and curvature only make it larger. So the :data:`NOISE_QUANTILE`
    quantile of them, divided by that chi variable's same quantile, is sigma wherever at least
    that share of the neighbourhoods is flat (in a cluttered tray the median was 3 to 7 mm on a
    noise-free cloud, edges everywhere). None for fewer than :data:`NOISE_NEIGHBOURS` + 1 points.
    """
    from scipy.spatial import cKDTree
    from scipy.stats import chi2

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    k = NOISE_NEIGHBOURS
    if len(p) <= k:
        return None
    step = max(1, len(p) // NOISE_SAMPLES)
    _, idx = cKDTree(p).query(p[::step], k=k)
    nb = p[idx]
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred) / (k - 3)
    smallest = np.linalg.eigvalsh(cov)[:, 0]
    local = np.sqrt(np.maximum(smallest, 0.0))
    scale = math.sqrt(chi2.ppf(NOISE_QUANTILE, k - 3) / (k - 3))
    return float(np.quantile(local, NOISE_QUANTILE) / scale), len(idx)


def derived_clearance(plane: SupportPlane | None, points: ArrayLike | None = None) -> tuple[float, str]:
    """The default clearance [m] and how it was derived.

    3 sigma of the support plane's residuals; without a plane, 3 sigma of the surfaces' noise
    (:func:`surface_noise` of ``points``, the cloud near the object); at least :data:`MIN_CLEARANCE`.
    :data:`DEFAULT_CLEARANCE` only when neither can be measured.
    """
    if plane is None:
        noise = None if points is None else surface_noise(points)
        if noise is None:
            return (
                DEFAULT_CLEARANCE,
                "default: no support plane fitted and too few points to measure the noise",
            )
        sigma, n = noise
        metres = max(CLEARANCE_SIGMAS * sigma, MIN_CLEARANCE)
        floor = f", at least {MIN_CLEARANCE * 1e3:.0f} mm" if metres == MIN_CLEARANCE else ""
        return metres, (
            f"3 sigma of the surfaces' noise near the object, no support plane fitted (sigma {sigma * 1e3:.1f} mm, "
            f"{NOISE_QUANTILE:.0%} quantile of {n} local plane fits{floor})"
        )
    sigma = plane.slab.sigma
    metres = max(CLEARANCE_SIGMAS * sigma, MIN_CLEARANCE)
    floor = f", at least {MIN_CLEARANCE * 1e3:.0f} mm" if metres == MIN_CLEARANCE else ""
    return metres, (
        f"3 sigma of the support plane's residuals (sigma {sigma * 1e3:.1f} mm, {plane.slab.points} points{floor})"
    )


def check_clearance(clearance: float | None) -> None:
    """Raise InputError unless ``clearance`` is None or a finite distance in [0, :data:`MAX_CLEARANCE`] [m]."""
    if clearance is None:
        return
    if not (
        isinstance(clearance, int | float) and math.isfinite(clearance) and 0 <= clearance <= MAX_CLEARANCE
    ):
        raise InputError(f"clearance must be a finite distance in [0, {MAX_CLEARANCE}] m, got {clearance}")


def fine_groups(
    groups: dict[str, VoxelMap],
    object_voxels: VoxelMap,
    points: ArrayLike,
    grasped: GraspedObject,
    slab: SupportSlab | None,
    radius: float = RADIUS,
) -> tuple[dict[str, Group], Group]:
    """The groups with their voxels near the object replaced by their points' :data:`FINE` cells.

    Args:
        groups: name -> 25 mm voxels (e.g. "support", "obstacle"), as
            :func:`~baseplace.world.environment.contact_groups` splits them.
        object_voxels: the grasped object's voxels.
        points: (N, 3) the cloud the voxels were made from [m].
        grasped: the grasped object.
        slab: the fitted support plane, or None (then no plane: its points stay cells).
        radius: voxels whose centre lies within this horizontal distance [m] of the object's
            footprint are replaced.

    Returns:
        The groups (each near voxel's points in fine cells of the same group, the object's points
        in fine cells of the object, the plane's points as :data:`SUPPORT_PLANE`) and the object.
    """
    res = object_voxels.resolution
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    near = {name: grasped.footprint_distance(v.centres[:, :2]) <= radius if len(v) else np.zeros(0, bool)
            for name, v in [*groups.items(), (_OBJECT, object_voxels)]}  # fmt: skip
    keys = np.floor(p / res).astype(np.int64)
    owner = np.full(len(p), -1)
    names = list(near)
    for k, name in enumerate(names):
        v = groups[name] if name != _OBJECT else object_voxels
        if near[name].any():
            owner[rows_in(keys, v.keys[near[name]])] = k
    taken = owner >= 0
    p, owner = p[taken], owner[taken]
    is_object = _object_points(p, grasped)
    plane = None
    if slab is not None:
        r = p[:, 2] - slab.height(p[:, :2])
        flat = ~is_object & (r <= slab.margin) & (r >= -slab.depth)
        plane = _plane(slab, p[flat])
        if plane is not None:
            p, owner, is_object = p[~flat], owner[~flat], is_object[~flat]
    moved = denoised(p)  # the noise once: the clearance stands on the surface, not on the noise
    out: dict[str, Group] = {}
    for k, name in enumerate(names):
        coarse = (groups[name] if name != _OBJECT else object_voxels).without(near[name])
        mine = is_object if name == _OBJECT else (owner == k) & ~is_object
        if name == _OBJECT:  # an object voxel's other points are obstacles
            mine_other = (owner == k) & ~is_object
            out["obstacle"] = _joined(out.get("obstacle"), _cells(moved[mine_other]))
        fine = _cells(moved[mine])
        out[name] = _joined(out.get(name), coarse, fine)
    grasped_group = out.pop(_OBJECT)
    out = {name: g for name, g in out.items() if group_size(g)}
    if plane is not None:
        out[SUPPORT_PLANE] = plane
    return out, grasped_group


_OBJECT = "\0object"


def denoised(points: ArrayLike) -> FloatArray:
    """The points (N, 3) [m] with their noise across their surface taken out, corners kept.

    A point whose :data:`NOISE_NEIGHBOURS` nearest neighbours are planar (the plane fitted to them
    leaves residuals of at most :data:`PLANAR_FACTOR` times the surfaces' noise,
    :func:`surface_noise`) goes onto that plane. A point at an edge or a corner, whose neighbours
    lie on two faces, is not put onto that fit (a plane through both faces would cut the corner
    off); instead, for each planar neighbour's plane (a face near it) on whose far side from the
    neighbourhood it lies, it goes back onto that plane: at a convex edge the far side is outside
    the solid, so the point ends on the solid's faces, never inside (but for the fits' own error,
    about sigma / sqrt(k)); at a concave one (a bottle's foot on a table) the neighbourhood lies
    outside the solid and the move is outward. No point at an edge moves by more than
    :data:`MAX_MOVE_SIGMAS` times the noise per face (a larger offset is shape, not noise). All
    stay where they were measured when the noise cannot be measured. On a curved surface the fitted
    plane lies inside it by about rho^2 / (8 r) (rho the neighbourhood's radius, r the curvature's):
    2.6 mm on a 3 cm bottle sampled every centimetre.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    noise = surface_noise(p)
    if noise is None:
        return p
    k, sigma = NOISE_NEIGHBOURS, noise[0]
    _, idx = cKDTree(p).query(p, k=k)
    nb = p[idx]
    centre = nb.mean(axis=1)
    centred = nb - centre[:, None, :]
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred) / (k - 3))
    normal = vectors[:, :, 0]
    planar = np.sqrt(np.maximum(values[:, 0], 0.0)) <= PLANAR_FACTOR * sigma
    out = p.copy()
    out[planar] -= np.einsum("ni,ni->n", p[planar] - centre[planar], normal[planar])[:, None] * normal[planar]
    edge = np.flatnonzero(~planar)
    for j in range(1, k):  # the planes of the edge points' planar neighbours, nearest first
        face = idx[edge, j]
        use = planar[face]
        e, f = edge[use], face[use]
        n, c = normal[f], centre[f]
        # which side of the face the point's neighbourhood lies on (0: on it)
        side = np.einsum("nki,ni->n", p[idx[e]] - c[:, None, :], n) / k
        offset = np.einsum("ni,ni->n", out[e] - c, n)
        far = ((offset * side < 0) | (np.abs(side) < sigma / 2)) & (np.abs(offset) <= MAX_MOVE_SIGMAS * sigma)
        out[e[far]] -= offset[far, None] * n[far]
    return out


def _object_points(p: FloatArray, grasped: GraspedObject) -> NDArray[np.bool_]:
    """(N,) True for the points (N, 3) on the object.

    Those within :data:`OBJECT_TOLERANCE` of its footprint and no higher than that above its top;
    for a box or cylinder, above its bottom's cell; for points, also down to its support (a found
    object leaves out its foot, the band of its support), and every point in one of its cells.
    """
    if len(p) == 0:
        return np.zeros(0, dtype=bool)
    top = grasped.bottom + grasped.size[2]
    # a shape's lowest cell holds the support's surface too: not the object's
    low = grasped.bottom - DEPTH if grasped.kind == "points" else grasped.bottom + MAX_FINE / 2
    z_ok = (p[:, 2] >= low) & (p[:, 2] <= top + OBJECT_TOLERANCE)
    out = np.zeros(len(p), dtype=bool)
    if z_ok.any():
        out[z_ok] = grasped.footprint_distance(p[z_ok, :2]) <= OBJECT_TOLERANCE
    if grasped.kind == "points":
        mine = np.unique(np.floor(grasped.points / FINE).astype(np.int64), axis=0)
        out |= rows_in(np.floor(p / FINE).astype(np.int64), mine)
    return out


def _cells(p: FloatArray) -> VoxelMap:
    # finer than a user may ask of VoxelMap.from_points: these are the few points near the object
    return VoxelMap(FINE, np.unique(np.floor(p / FINE).astype(np.int64).reshape(-1, 3), axis=0))


def _joined(group: Group | None, *parts: VoxelMap) -> Group:
    """A group of the non-empty parts (merged per resolution)."""
    by_res: dict[float, list[NDArray[np.int64]]] = {}
    for part in [*(group_parts(group) if group is not None else ()), *parts]:
        if isinstance(part, VoxelMap) and len(part):
            by_res.setdefault(part.resolution, []).append(part.keys)
    merged = tuple(VoxelMap(r, np.unique(np.concatenate(k), axis=0)) for r, k in sorted(by_res.items()))
    if not merged:
        return VoxelMap(FINE, np.zeros((0, 3), dtype=np.int64))
    return merged[0] if len(merged) == 1 else merged


def _plane(slab: SupportSlab, p: FloatArray) -> SupportPlane | None:
    """The exact plane over the footprint of the points ``p`` (N, 3) it replaces, or None (too few)."""
    if len(p) < 3:
        return None
    try:
        hull = p[ConvexHull(p[:, :2]).vertices, :2]
    except (QhullError, ValueError):
        return None
    return SupportPlane(slab, hull, len(p))
