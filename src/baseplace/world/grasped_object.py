"""The grasped object: the one thing the robot may touch, and only with its hand.

Seed 000 (Algorithm 2) checks the whole robot at each IK solution against the scene's obstacle
voxels; at a grasp the closing hand surrounds the object, so the object's own voxels must not count
as obstacles for the hand. Everything else stays an obstacle for every link: the surface the object
stands on (its *support*), a tray's rim, the neighbouring objects, and the object itself for any
link that is not the hand.

The object is given explicitly (a box, an upright cylinder, a point set) or found from the grasp
(:func:`find_grasped_object`): the cloud's cluster at the grasp point, points linked by distance
(never by a grid, so the frame of the cloud does not matter), above the surface it stands on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.voxels import VoxelMap

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

SUPPORT_MARGIN = 0.15
"""Obstacle voxels this far [m] around the object's footprint, just below its bottom, are its support."""
SUPPORT_DEPTH = 0.1
"""How far [m] below the object's bottom its support voxels reach."""

OBJECT_SYNTAX = (
    '"auto", "none", "box CX CY CZ SX SY SZ [YAW]", "cylinder CX CY CZ RADIUS HEIGHT" or "points FILE"'
)


@dataclass(frozen=True)
class GraspedObject:
    """The object in the hand, in the world frame.

    Attributes:
        kind: "box" (centre, edge lengths ``size`` and ``yaw`` about z), "cylinder" (upright:
            centre, ``size`` = (2 r, 2 r, h)) or "points" (the voxels holding ``points``).
        center: (3,) centroid [m] (for "points": the mean of the points).
        size: (3,) extents along the object's x, y, z [m] (for "points": of its bounding box).
        yaw: rotation about world z [rad].
        points: (N, 3) points on the object [m] ("points" only; empty otherwise).
        source: "given" or "auto" (found from the grasp by :func:`find_grasped_object`).
    """

    kind: str
    center: FloatArray
    size: FloatArray
    yaw: float = 0.0
    points: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    source: str = "given"

    def __post_init__(self) -> None:
        # the object's own read-only copies: the footprint tree, built from the points on first use
        # and kept, cannot go stale by a change to an array the caller still holds
        for name in ("center", "size", "points"):
            value = np.array(getattr(self, name), dtype=float)
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @classmethod
    def box(cls, center: ArrayLike, size: ArrayLike, yaw: float = 0.0) -> GraspedObject:
        """A box of edge lengths ``size`` (3,) [m] centred at ``center`` (3,), turned by ``yaw`` [rad]."""
        c, s = _vector(center, 3, "box centre"), _vector(size, 3, "box size")
        if not np.all(s > 0) or not math.isfinite(yaw):
            raise InputError(
                f"a box needs positive edge lengths and a finite yaw, got {s.tolist()} and {yaw}"
            )
        return cls("box", c, s, float(yaw))

    @classmethod
    def cylinder(cls, center: ArrayLike, radius: float, height: float) -> GraspedObject:
        """An upright cylinder of ``radius`` and ``height`` [m] centred at ``center`` (3,)."""
        c = _vector(center, 3, "cylinder centre")
        if not (math.isfinite(radius) and math.isfinite(height) and radius > 0 and height > 0):
            raise InputError(f"a cylinder needs a positive radius and height, got {radius} and {height}")
        return cls("cylinder", c, np.array([2 * radius, 2 * radius, height], dtype=float))

    @classmethod
    def from_points(cls, points: ArrayLike, source: str = "given") -> GraspedObject:
        """The voxels holding ``points`` (N, 3) [m] on the object."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if len(p) == 0:
            raise InputError("the grasped object needs at least one finite point")
        lo, hi = p.min(axis=0), p.max(axis=0)
        return cls("points", (lo + hi) / 2, hi - lo, 0.0, p, source)

    @property
    def bottom(self) -> float:
        """Height [m] of the object's lowest point."""
        return float(self.center[2] - self.size[2] / 2)

    def _local(self, xyz: FloatArray) -> FloatArray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = xyz - self.center
        return np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]]

    def footprint_distance(self, xy: ArrayLike) -> FloatArray:
        """Horizontal distance (N,) [m] of xy points (N, 2) from the object's footprint (0 inside)."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self.kind == "points":
            dist, _ = self._footprint_tree.query(p)
            return np.asarray(dist, dtype=float)
        local = self._local(np.c_[p, np.full(len(p), self.center[2])])
        if self.kind == "cylinder":
            return np.maximum(np.hypot(local[:, 0], local[:, 1]) - self.size[0] / 2, 0.0)
        gap = np.maximum(np.abs(local[:, :2]) - self.size[:2] / 2, 0.0)  # a box
        return np.hypot(gap[:, 0], gap[:, 1])

    def footprint_within(self, xy: ArrayLike, radius: float) -> NDArray[np.bool_]:
        """(N,) True for the xy points (N, 2) within ``radius`` [m] of the footprint: ``footprint_distance(xy) <= radius``.

        For an object of points a full nearest-neighbour query of each of a cloud's points cost a
        fifth of a ``place`` on the PCL mug cloud. So a point farther than ``radius`` from the
        object's bounding box is out, one within ``radius`` of one of a few of the object's points
        (its extremes along x and y) is in, and only the others are looked up in the object's
        tree, by a search that stops at ``radius``. Each verdict is exact.
        """
        if self.kind != "points":
            return self.footprint_distance(xy) <= radius
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        obj = self.points[:, :2]
        lo, hi = obj.min(axis=0) - radius, obj.max(axis=0) + radius
        near = np.flatnonzero(np.all((p >= lo) & (p <= hi), axis=1))
        out = np.zeros(len(p), dtype=bool)
        for c in obj[[*obj.argmin(axis=0), *obj.argmax(axis=0)]]:
            d = p[near] - c
            out[near] |= np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) <= radius  # as the tree computes it
        near = near[~out[near]]
        # the search's bound is strict: one step above radius, then the same comparison as above
        dist, _ = self._footprint_tree.query(p[near], distance_upper_bound=math.nextafter(radius, math.inf))
        out[near] = dist <= radius
        return out

    @cached_property
    def _footprint_tree(self) -> cKDTree:
        """The object's points in the plane (for an object of points), built on first use."""
        from scipy.spatial import cKDTree

        return cKDTree(self.points[:, :2])

    def voxel_mask(self, voxels: VoxelMap) -> NDArray[np.bool_]:
        """(M,) True for the voxels that hold the object.

        For a box or cylinder: the voxels whose cube intersects the shape (exact: separating axes
        for the box, the closest point of the voxel's square for the cylinder), except the layer
        whose centres lie within half a voxel above the bottom face: it holds the support's
        surface too, and stays an obstacle. For points: the voxels that hold one.
        """
        if len(voxels) == 0:
            return np.zeros(0, dtype=bool)
        res = voxels.resolution
        h = res / 2
        if self.kind == "points":
            keys = np.unique(np.floor(self.points / res).astype(np.int64), axis=0)
            return rows_in(voxels.keys, keys)
        c = voxels.centres
        half = self.size / 2
        z_ok = (c[:, 2] >= self.center[2] - half[2] + h) & (c[:, 2] <= self.center[2] + half[2] + h)
        d = c[:, :2] - self.center[:2]
        if self.kind == "cylinder":
            gap = np.maximum(np.abs(d) - h, 0.0)
            return z_ok & (np.hypot(gap[:, 0], gap[:, 1]) <= half[0])
        cos, sin = abs(math.cos(self.yaw)), abs(math.sin(self.yaw))
        local = self._local(c)
        along_object = np.all(np.abs(local[:, :2]) <= half[:2] + h * (cos + sin), axis=1)
        along_world = (np.abs(d[:, 0]) <= h + half[0] * cos + half[1] * sin) & (
            np.abs(d[:, 1]) <= h + half[0] * sin + half[1] * cos
        )
        return z_ok & along_object & along_world

    def support_mask(self, voxels: VoxelMap) -> NDArray[np.bool_]:
        """(M,) True for the voxels of the surface the object stands on, near it.

        Voxels within :data:`SUPPORT_MARGIN` of the footprint whose centre lies between
        :data:`SUPPORT_DEPTH` below the object's bottom and half a voxel above it.
        """
        if len(voxels) == 0:
            return np.zeros(0, dtype=bool)
        c = voxels.centres
        z = c[:, 2]
        band = (z >= self.bottom - SUPPORT_DEPTH) & (z <= self.bottom + voxels.resolution / 2)
        out = np.zeros(len(c), dtype=bool)
        if band.any():
            out[band] = self.footprint_within(c[band, :2], SUPPORT_MARGIN)
        return out

    def to_json(self) -> dict[str, Any]:
        """What the robot was allowed to touch, for results files."""
        out: dict[str, Any] = {"kind": self.kind, "source": self.source,
                               "center": np.round(self.center, 4).tolist(), "size": np.round(self.size, 4).tolist(),
                               "allowed": "hand links only"}  # fmt: skip
        if self.kind == "box":
            out["yaw"] = round(self.yaw, 5)
        if self.kind == "points":
            out["points"] = len(self.points)
        return out


def _vector(value: ArrayLike, n: int, what: str) -> FloatArray:
    v = np.asarray(value, dtype=float).reshape(-1)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} must be {n} finite numbers [m], got {np.asarray(value).tolist()}")
    return v


def rows_in(keys: NDArray[np.int64], table: NDArray[np.int64]) -> NDArray[np.bool_]:
    """(M,) True where a row of ``keys`` (M, 3) is a row of ``table`` (T, 3)."""
    if len(table) == 0 or len(keys) == 0:
        return np.zeros(len(keys), dtype=bool)
    lo = np.minimum(keys.min(axis=0), table.min(axis=0))
    span = np.maximum(keys.max(axis=0), table.max(axis=0)) - lo + 1

    def flat(k: NDArray[np.int64]) -> NDArray[np.int64]:
        return ((k[:, 0] - lo[0]) * span[1] + (k[:, 1] - lo[1])) * span[2] + (k[:, 2] - lo[2])

    return np.isin(flat(keys), flat(table))


def parse_grasped_object(text: str, what: str = "--object") -> GraspedObject | str | None:
    """Parse the ``--object`` syntax (see :data:`OBJECT_SYNTAX`).

    "auto", "none", a box or an upright cylinder [m, rad], or "points FILE", a cloud of the
    object in the world frame (any format :func:`~baseplace.terrain.io.load_cloud` reads).

    Returns:
        "auto", None (for "none") or the given :class:`GraspedObject`.
    """
    words = text.replace(",", " ").split()
    if not words:
        raise InputError(f"{what} must be {OBJECT_SYNTAX}, got {text!r}")
    kind = words[0].lower()
    if kind == "points" and len(words) == 2:
        from baseplace.terrain.io import load_cloud

        return GraspedObject.from_points(load_cloud(words[1]).points)
    if kind in ("auto", "none") and len(words) == 1:
        return kind if kind == "auto" else None
    try:
        values = [float(v) for v in words[1:]]
    except ValueError:
        raise InputError(f"{what} must be {OBJECT_SYNTAX}, got {text!r}") from None
    if kind == "box" and len(values) in (6, 7):
        return GraspedObject.box(values[:3], values[3:6], values[6] if len(values) == 7 else 0.0)
    if kind == "cylinder" and len(values) == 5:
        return GraspedObject.cylinder(values[:3], values[3], values[4])
    raise InputError(f"{what} must be {OBJECT_SYNTAX}, got {text!r}")


@dataclass(frozen=True)
class AutoSettings:
    """How :func:`find_grasped_object` cuts the object out of the cloud.

    Attributes:
        link: two points closer than this [m] belong to the same cluster; less than the smallest
            gap between two objects that must stay apart (2 cm: a 3 cm gap always stays open,
            whatever the cloud's frame).
        spacing: the cloud is thinned to points at least this far apart [m] before linking (each
            point keeps the thinned point that covers it); gaps up to ``link - 2 spacing`` are
            always bridged.
        seed_radius: the cluster starts at the cloud's point nearest the grasp point, within this [m].
        max_size: largest horizontal extent (diameter) of an object [m]; when the cluster grows
            wider than this on the way down, it has reached the object's support.
        support_gap: points less than this [m] above the height where the support joins are the
            support's surface (and its noise): they stay obstacles.
        step: height step [m] of the search for the support.
        depth: how far below the grasp point the object may reach [m].
        voxel_size: the collision voxels' edge [m]: the object keeps only the points in collision
            voxels that hold no other point.
        shared: a part of the cluster joined to the object only by links whose two points share
            fewer than this many neighbours within ``link`` (and fewer than all but one of the
            fewer either has: :func:`_shared_links`) is left out when it is an object's size
            (:func:`_without_joined`): one pair of noisy points across a gap does not join two
            objects. At 4 mm noise single linkage joined a neighbour 3.1-3.5 cm from the bottle in
            3 of 30 find-rate dev scenes (25002, 25008, 25028), each through one pair of points
            1.7-1.9 cm apart (session 20). 0: single linkage only.
    """

    link: float = 0.02
    spacing: float = 0.004
    seed_radius: float = 0.06
    max_size: float = 0.3
    support_gap: float = 0.015
    step: float = 0.002
    depth: float = 0.6
    voxel_size: float = 0.025
    shared: int = 2

    def __post_init__(self) -> None:
        values = (
            self.link,
            self.spacing,
            self.seed_radius,
            self.max_size,
            self.step,
            self.depth,
            self.voxel_size,
        )
        if not all(math.isfinite(v) and v > 0 for v in values) or not (0 <= self.support_gap < self.depth):
            raise InputError(f"auto-object settings must be positive lengths [m], got {self}")
        if not isinstance(self.shared, int) or self.shared < 0:
            raise InputError(f"auto-object shared neighbours must be a count >= 0, got {self.shared!r}")
        if 2 * self.spacing >= self.link:
            raise InputError(f"spacing ({self.spacing} m) must be under half the link ({self.link} m)")


def grasped_cluster(
    points: ArrayLike, grasp_point: ArrayLike, settings: AutoSettings | None = None
) -> NDArray[np.bool_] | None:
    """(N,) True for the points of the object at ``grasp_point`` (3,), above the surface it stands on.

    Points (N, 3) [m] of a z-up world cloud are linked when they lie within ``link`` of each other
    (after thinning to ``spacing``); the cluster is grown from the point nearest the grasp point.
    Going down from there in ``step``s, the cluster of the points above each height is followed
    until its horizontal diameter exceeds ``max_size``: there the support (a table top, a tray
    bottom) has joined. The object is the cluster just above that height, less the points within
    ``support_gap`` above it. Only distances and heights relative to the start point enter, so
    the result does not change when the cloud is shifted or turned about z.

    Returns:
        The mask, or None when no point lies within ``seed_radius`` of the grasp point, the grasp
        point lies on the support itself, or the cluster is wider than ``max_size``.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    s = settings or AutoSettings()
    g = _vector(grasp_point, 3, "grasp point")
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    reach = s.max_size + s.link
    near = np.all(np.isfinite(p), axis=1)
    near[near] = (np.hypot(p[near, 0] - g[0], p[near, 1] - g[1]) <= reach) & (
        np.abs(p[near, 2] - g[2] + (s.depth - s.max_size) / 2) <= (s.depth + s.max_size) / 2
    )
    index = np.flatnonzero(near)
    local = p[index]
    if len(local) == 0:
        return None
    d = np.linalg.norm(local - g, axis=1)
    start = int(np.argmin(d))
    if d[start] > s.seed_radius:
        return None
    from baseplace.world.thinning import thin_in_order

    keep, owner = thin_in_order(local, s.spacing)
    thin = local[keep]
    pairs = cKDTree(thin).query_pairs(s.link, output_type="ndarray")
    n = len(thin)
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    seed = int(owner[start])
    z_seed = float(thin[seed, 2])

    def cluster(floor: float) -> NDArray[np.bool_]:
        """The thinned points linked to the seed through points at or above ``floor``."""
        above = np.flatnonzero(thin[:, 2] >= floor)
        out = np.zeros(n, dtype=bool)
        where = np.searchsorted(above, seed)
        if where == len(above) or above[where] != seed:
            return out
        _, labels = connected_components(graph[above][:, above], directed=False)
        out[above[labels == labels[where]]] = True
        return out

    # the cluster only grows as the floor goes down: bisect for the first floor where it is too wide
    steps = int(s.depth / s.step)
    lo, hi = 0, steps + 1  # cluster(z_seed - k step) is narrow for k < lo, too wide for k >= hi
    while lo < hi:
        mid = (lo + hi) // 2
        if _wider_than(thin[cluster(z_seed - mid * s.step), :2], s.max_size):
            hi = mid
        else:
            lo = mid + 1
    if hi <= steps:  # the support joins at this height
        if hi == 0:
            return None  # the grasp point lies on the support (a table top, a wall)
        floor = z_seed - hi * s.step + s.support_gap
    else:
        floor = z_seed - s.depth
    mine = cluster(floor)
    if not mine.any() or _wider_than(thin[mine, :2], s.max_size):
        return None
    if s.shared:
        mine = _without_joined(mine, seed, graph, _shared_links(pairs, n, s.shared))
    chosen = mine[owner] & (local[:, 2] >= floor)
    out = np.zeros(len(p), dtype=bool)
    out[index[chosen]] = True
    return out


JOINED_PIECE = 60
"""A part of the cluster this many thinned points large, joined to the seed's part only by links
without shared neighbours, is another object (:func:`_without_joined`); a smaller one is the
object's own noise and stays."""


def _without_joined(mine: NDArray[np.bool_], seed: int, single: Any, shared: Any) -> NDArray[np.bool_]:
    """The cluster ``mine`` (n,) less another object that only weak links join to the seed's part.

    ``single``: every link (n, n); ``shared``: the links with shared neighbours
    (:func:`_shared_links`). The seed's part under ``shared`` is the object when what it leaves of
    ``mine`` holds a connected piece (under ``single``) of :data:`JOINED_PIECE` points or more: a
    neighbour joined through a noisy pair. Otherwise ``mine`` stays whole, so a cluster single
    linkage already keeps apart comes out exactly as before (and does not depend on which points
    thinning kept).
    """
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(mine)
    where = int(np.searchsorted(idx, seed))
    _, labels = connected_components(shared[idx][:, idx], directed=False)
    strong = labels == labels[where]
    rest = idx[~strong]
    if len(rest) < JOINED_PIECE:
        return mine
    _, pieces = connected_components(single[rest][:, rest], directed=False)
    if np.bincount(pieces).max() < JOINED_PIECE:
        return mine
    out = np.zeros_like(mine)
    out[idx[strong]] = True
    return out


def _shared_links(pairs: NDArray[np.int64], n: int, shared: int) -> Any:
    """The graph (n, n) of the pairs (P, 2) of n points that have ``shared`` neighbours in common.

    Single linkage joins two objects through one pair of noisy points across their gap: such a pair
    has no neighbours in common (the gap between them is empty), while two points of one surface
    share most of theirs (Jarvis and Patrick's shared-neighbour rule). A pair is kept when at least
    ``shared`` other points are paired with both, or all but one of the fewer neighbours either
    point has (a lone point at a sparse rim keeps its links); ``shared`` 0: every pair (single
    linkage). Returns a ``scipy.sparse`` CSR matrix, one entry per kept pair.
    """
    from scipy.sparse import coo_matrix

    ones = np.ones(2 * len(pairs), dtype=np.int32)
    rows, cols = np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]
    A = coo_matrix((ones, (rows, cols)), shape=(n, n)).tocsr()
    degree = np.diff(A.indptr)
    # (A A)_ij counts the common neighbours of i and j; read at the pairs only (A's pattern)
    common = np.asarray((A @ A).multiply(A).tocsr()[pairs[:, 0], pairs[:, 1]]).ravel()
    fewer = np.minimum(degree[pairs[:, 0]], degree[pairs[:, 1]])  # each counts the other too
    kept = pairs[common >= np.minimum(shared, fewer - 2)]
    return coo_matrix((np.ones(len(kept), dtype=np.int8), (kept[:, 0], kept[:, 1])), shape=(n, n)).tocsr()


def _wider_than(xy: FloatArray, size: float) -> bool:
    """Whether two of the points (M, 2) [m] lie more than ``size`` apart (the set's diameter)."""
    if len(xy) < 2:
        return False
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    if float(np.max(hi - lo)) > size:
        return True
    if float(np.hypot(*(hi - lo))) <= size:
        return False
    from scipy.spatial import ConvexHull, QhullError

    try:
        xy = xy[ConvexHull(xy).vertices]
    except QhullError:  # collinear or too few: the extreme points along the main direction
        axis = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)[2][0]
        t = xy @ axis
        xy = xy[[int(np.argmin(t)), int(np.argmax(t))]]
    diff = xy[:, None, :] - xy[None, :, :]
    return bool(np.sqrt((diff**2).sum(axis=-1)).max() > size)


def find_grasped_object(
    points: ArrayLike, grasp_point: ArrayLike, settings: AutoSettings | None = None
) -> GraspedObject | None:
    """The object at ``grasp_point`` (3,): the cloud's cluster there, above the surface it stands on.

    The points (N, 3) [m] of a z-up world cloud that :func:`grasped_cluster` finds, less those in
    collision voxels (``voxel_size``, on the obstacles' world grid) that also hold a point of
    anything else, so that the support and the neighbours stay obstacles.

    Returns:
        The object (kind "points", source "auto"), or None when :func:`grasped_cluster` finds
        none or every voxel of the cluster is shared with something else.
    """
    s = settings or AutoSettings()
    mask = grasped_cluster(points, grasp_point, s)
    if mask is None:
        return None
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = p[mask].min(axis=0) - s.voxel_size, p[mask].max(axis=0) + s.voxel_size
    around = np.all((p >= lo) & (p <= hi), axis=1)  # only these can share a voxel with the object
    keys = np.floor(p[around] / s.voxel_size).astype(np.int64)
    mine = mask[around]
    mixed = rows_in(keys[mine], np.unique(keys[~mine], axis=0))
    if mixed.all():
        return None
    return GraspedObject.from_points(p[around][mine][~mixed], source="auto")
