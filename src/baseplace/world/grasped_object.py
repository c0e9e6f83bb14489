"""The grasped object: the one thing the robot may touch, and only with its hand.

Seed 000 (Algorithm 2) checks the whole robot at each IK solution against the scene's obstacle
voxels; at a grasp the closing hand surrounds the object, so the object's own voxels must not count
as obstacles for the hand. Everything else stays an obstacle for every link: the surface the object
stands on (its *support*), a tray's rim, the neighbouring objects, and the object itself for any
link that is not the hand.

The object is given explicitly (a box, an upright cylinder, a point set) or found from the grasp
(:func:`find_grasped_object`): the cloud's connected cluster at the grasp point, above the surface
it stands on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.voxels import VoxelMap

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
        local = self._local(np.c_[p, np.full(len(p), self.center[2])])
        if self.kind == "cylinder":
            return np.maximum(np.hypot(local[:, 0], local[:, 1]) - self.size[0] / 2, 0.0)
        if self.kind == "box":
            gap = np.maximum(np.abs(local[:, :2]) - self.size[:2] / 2, 0.0)
            return np.hypot(gap[:, 0], gap[:, 1])
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(self.points[:, :2]).query(p)
        return np.asarray(dist, dtype=float)

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
            out[band] = self.footprint_distance(c[band, :2]) <= SUPPORT_MARGIN
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
        cell: edge of the fine voxels the cluster grows through [m]; at most half the smallest
            gap between two objects that must stay apart (1.5 cm: a 3 cm gap stays open).
        seed_radius: the cluster starts at the cloud's point nearest the grasp point, within this [m].
        max_size: largest horizontal extent of an object [m]; a layer wider than this under the
            grasp point is its support.
        depth: how far below the grasp point the object may reach [m].
        voxel_size: the collision voxels' edge [m]: the object keeps only the points in collision
            voxels that hold no other point.
    """

    cell: float = 0.015
    seed_radius: float = 0.06
    max_size: float = 0.3
    depth: float = 0.6
    voxel_size: float = 0.025


def find_grasped_object(
    points: ArrayLike, grasp_point: ArrayLike, settings: AutoSettings | None = None
) -> GraspedObject | None:
    """The object at ``grasp_point`` (3,): the cloud's cluster there, above the surface it stands on.

    The points (N, 3) [m] of a z-up world cloud near the grasp point go into fine voxels
    (``cell``). From the voxel nearest the grasp point, layer by layer downwards, the object's
    horizontal section is followed (8-connected, overlapping the section above) until a layer's
    section grows wider than ``max_size``: that layer is the support. The object is the
    26-connected cluster of the start voxel in the layers above the support, less the layer just
    above it (noise of the support's surface). Its points are those in collision voxels that hold
    no other point, so that the support and the neighbours stay obstacles.

    Returns:
        The object (kind "points", source "auto"), or None when no point lies within
        ``seed_radius`` of the grasp point or the cluster is wider than ``max_size`` (the grasp
        point is on a large surface, which stays an obstacle).
    """
    s = settings or AutoSettings()
    g = _vector(grasp_point, 3, "grasp point")
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    near = (np.abs(p[:, 0] - g[0]) <= s.max_size) & (np.abs(p[:, 1] - g[1]) <= s.max_size)
    near &= (p[:, 2] >= g[2] - s.depth) & (p[:, 2] <= g[2] + s.max_size)
    local = p[near]
    if len(local) == 0:
        return None
    d = np.linalg.norm(local - g, axis=1)
    if d.min() > s.seed_radius:
        return None
    lo = np.floor(local.min(axis=0) / s.cell).astype(np.int64) - 1
    idx = np.floor(local / s.cell).astype(np.int64) - lo
    shape = tuple(int(v) for v in idx.max(axis=0) + 2)
    occ = np.zeros(shape, dtype=bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    seed = idx[int(np.argmin(d))]
    support_level = _support_level(occ, seed, s.max_size / s.cell)
    above = occ.copy()
    above[:, :, : support_level + 2] = False  # the support's layer and the one above it
    labels, _ = ndimage.label(above, structure=np.ones((3, 3, 3), dtype=bool))
    lab = labels[seed[0], seed[1], seed[2]]
    if lab == 0:  # the grasp point sits on the support itself
        return None
    mine = labels[idx[:, 0], idx[:, 1], idx[:, 2]] == lab
    extent = local[mine, :2].max(axis=0) - local[mine, :2].min(axis=0)
    if float(extent.max()) > s.max_size:  # a table top or a wall, not an object in the hand
        return None
    keys = np.floor(local / s.voxel_size).astype(np.int64)
    mixed = rows_in(keys[mine], np.unique(keys[~mine], axis=0))
    if mixed.all():
        return None
    return GraspedObject.from_points(local[mine][~mixed], source="auto")


def _support_level(occ: NDArray[np.bool_], seed: NDArray[np.int64], max_cells: float) -> int:
    """The z index of the first layer below ``seed`` whose section under the object is wider than ``max_cells``."""
    eight = np.ones((3, 3), dtype=bool)
    labels, _ = ndimage.label(occ[:, :, seed[2]], structure=eight)
    section = labels == labels[seed[0], seed[1]]
    for z in range(seed[2] - 1, -1, -1):
        layer = occ[:, :, z]
        labels, _ = ndimage.label(layer, structure=eight)
        under = np.unique(labels[ndimage.binary_dilation(section, eight) & layer])
        under = under[under > 0]
        if len(under) == 0:
            continue  # a gap (unseen underside): keep the section from above
        grown = np.isin(labels, under)
        rows, cols = np.nonzero(grown)
        if max(rows.max() - rows.min(), cols.max() - cols.min()) + 1 > max_cells:
            return z
        section = grown
    return -2
