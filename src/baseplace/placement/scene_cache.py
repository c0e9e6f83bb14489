"""What every placement query in one scene shares, built once (issue 18: per-query cost).

A robot asks "where do I stand?" many times in the same scene. The segmentation, the obstacle
voxels and the collision environment (its OcTrees) depend on the scene and, for the allowed
contact, on the grasped object, never on the target: :class:`SceneCache` keeps them between
queries of :func:`~baseplace.placement.pipeline.place`. The robot's own collision model and
pair tables are cached per robot already (:mod:`baseplace.world.environment`).

Environments carry mutable pinocchio data: one query at a time per cache (the service holds a
lock per scene).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.pipeline import Terrain, terrain_from_points
from baseplace.world.grasped_object import GraspedObject

T = TypeVar("T")

OBJECT_ENVIRONMENTS = 8
"""Collision environments kept per scene for distinct grasped objects, and objects found per grasp
point (least recently used go)."""

OSRMS = 8
"""OSRMs kept per scene for distinct targets (least recently used go): a robot that asks again for
the same grasp (another seed, after a failed attempt) finds the map of its base poses made."""

NEAR_GRASP_MARGIN = 0.05
"""Margin [m] of the cloud window in which :meth:`SceneCache.grasped_object` seeks the object, beyond
the largest distance :func:`~baseplace.world.grasped_object.find_grasped_object` reads a point at."""

NEAR_CELL = 0.25
"""Cell of the grid that finds a cloud's points near a point [m]."""


class Same:
    """A cache key part that is one object, by identity (arrays and maps hash by no value of theirs).

    It holds the object: an id() of a collected one could come back for another.
    """

    __slots__ = ("obj",)

    def __init__(self, obj: object) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Same) and other.obj is self.obj


def object_key(obj: GraspedObject | None) -> str:
    """A digest of what the allowed contact depends on: the object's kind, pose, size and points."""
    if obj is None:
        return "none"
    h = hashlib.sha256(obj.kind.encode())
    for a in (obj.center, obj.size, np.array([obj.yaw]), obj.points):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:24]


class SceneCache:
    """One scene's segmentation, obstacle voxels and collision environments, kept between queries.

    Args:
        points: (N, 3) z-up world cloud of the scene [m] (non-finite rows are dropped).
        terrain: a segmentation of the same cloud, if already made.
        resolution: the height-map cell ``terrain`` was made with (None: chosen from the cloud).
    """

    def __init__(
        self, points: ArrayLike, terrain: Terrain | None = None, resolution: float | None = None
    ) -> None:
        self._raw = np.asarray(points, dtype=float).reshape(-1, 3)
        self._points: FloatArray | None = None
        self._index: tuple[FloatArray, Any, Any, float, int, Any] | None = None
        self._bounds: tuple[FloatArray, FloatArray] | None = None
        self._found: OrderedDict[bytes, GraspedObject | None] = OrderedDict()
        self._terrains: dict[float | None, Terrain] = {}
        if terrain is not None:
            self._terrains[resolution] = terrain
        self._shared: dict[Hashable, Any] = {}
        self._objects: OrderedDict[Hashable, Any] = OrderedDict()
        self._osrms: OrderedDict[Hashable, Any] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    @property
    def points(self) -> FloatArray:
        """The finite points (N, 3) of the cloud [m]."""
        if self._points is None:
            finite = np.all(np.isfinite(self._raw), axis=1)
            self._points = self._raw if finite.all() else self._raw[finite]
            if len(self._points) == 0:
                raise InputError("the cloud has no finite points")
        return self._points

    @property
    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper corners (3,) of the finite points [m], found once."""
        if self._bounds is None:
            if not np.isfinite(self._raw).all(axis=1).any():  # the jobs' message for a cloud without any
                raise InputError("the cloud holds no finite points")
            self._bounds = (self.points.min(axis=0), self.points.max(axis=0))
        return self._bounds

    def prepare(self) -> None:
        """Build now what every query reads whatever its target: the bounds and the grid of :meth:`points_near`.

        A service calls it on a scene's upload, so that no query pays it. A cloud without a finite
        point is left to the query, which refuses it.
        """
        if np.isfinite(self._raw).all(axis=1).any():
            self.bounds  # noqa: B018  found now, not in a query
            self.points_near(self.points[0], 0.0)

    def terrain(self, resolution: float | None = None) -> Terrain:
        """The segmentation at this height-map cell [m] (None: chosen from the cloud), made once."""
        given = self._terrains.get(resolution)
        if given is not None:
            return given
        return self.shared(
            ("terrain", resolution), lambda: terrain_from_points(self.points, resolution=resolution)
        )

    def points_near(self, xy: ArrayLike, half_width: float) -> FloatArray:
        """The points (M, 3) whose x and y lie within ``half_width`` [m] of ``xy`` (2,).

        In the order of the cloud sorted by x (stable), whatever the window. Found through a grid
        of :data:`NEAR_CELL` cells made once, so a query reads only the cells its window touches.
        """
        if self._index is None:
            pts = self.points
            lo = pts[:, :2].min(axis=0)
            ny = int(np.floor((pts[:, 1].max() - lo[1]) / NEAR_CELL)) + 1
            ij = np.floor((pts[:, :2] - lo) / NEAR_CELL).astype(np.int64)
            rank = np.empty(len(pts), dtype=np.int64)  # each point's place in the stable sort by x
            rank[np.argsort(pts[:, 0], kind="stable")] = np.arange(len(pts))
            order = np.argsort(ij[:, 0] * ny + ij[:, 1], kind="stable")
            keys = (ij[:, 0] * ny + ij[:, 1])[order]
            self._index = (pts[order], keys, rank[order], float(NEAR_CELL), ny, lo)
        cells, keys, rank, size, ny, lo = self._index
        x, y = (float(v) for v in np.asarray(xy, dtype=float)[:2])
        ix0, ix1 = (int(np.floor((v - lo[0]) / size)) for v in (x - half_width, x + half_width))
        iy0, iy1 = (int(np.floor((v - lo[1]) / size)) for v in (y - half_width, y + half_width))
        iy0, iy1 = max(iy0, 0), min(iy1, ny - 1)
        columns = np.arange(max(ix0, 0), max(ix1 + 1, 0))
        if len(columns) == 0 or iy0 > iy1:
            return np.empty((0, 3))
        starts = np.searchsorted(keys, columns * ny + iy0, side="left")
        ends = np.searchsorted(keys, columns * ny + iy1, side="right")
        take = np.concatenate([np.arange(a, b) for a, b in zip(starts, ends, strict=True)])
        window = cells[take]
        inside = (np.abs(window[:, 0] - x) <= half_width) & (np.abs(window[:, 1] - y) <= half_width)
        take = take[inside]
        return cells[take[np.argsort(rank[take])]]

    def grasped_object(self, grasp_point: ArrayLike) -> GraspedObject | None:
        """:func:`~baseplace.world.grasped_object.find_grasped_object` at ``grasp_point`` (3,), default settings.

        Sought in the window of the cloud it reads: the points within ``max_size + link`` of the
        grasp point (horizontally) and within ``voxel_size`` of the cluster's box, plus
        :data:`NEAR_GRASP_MARGIN`; the same object as in the whole cloud, its points in the order
        of :meth:`points_near`. What a grasp point found is kept (the last
        :data:`OBJECT_ENVIRONMENTS` points): the next query at the same point reads it.
        """
        from baseplace.world.grasped_object import AutoSettings, find_grasped_object

        point = np.asarray(grasp_point, dtype=np.float64).reshape(-1)
        a = AutoSettings()
        near = a.max_size + a.link + a.voxel_size + NEAR_GRASP_MARGIN
        return self._recent(
            self._found, point.tobytes(), lambda: find_grasped_object(self.points_near(point, near), point, a)
        )

    def shared(self, key: Hashable, make: Callable[[], T]) -> T:
        """The value for ``key``, made by ``make()`` on first use and kept for the scene's life.

        Safe to call from several threads: the tables are read and written under a lock, ``make``
        runs outside it (two threads may both make a value; the first one kept wins).
        """
        with self._lock:
            if key in self._shared:
                self.hits += 1
                return self._shared[key]
        value = make()
        with self._lock:
            if key not in self._shared:
                self.misses += 1
                self._shared[key] = value
            return self._shared[key]

    def per_object(self, key: Hashable, make: Callable[[], T]) -> T:
        """As :meth:`shared`, for values that depend on a grasped object: the last few are kept."""
        return self._recent(self._objects, key, make, count=True)

    def per_targets(self, key: Hashable, make: Callable[[], T]) -> T:
        """As :meth:`shared`, for values that depend on the targets (the OSRM): the last :data:`OSRMS` are kept.

        A store of their own: a query's new targets never push out a grasped object's environment.
        """
        return self._recent(self._osrms, key, make, limit=OSRMS)

    def _recent(
        self,
        store: OrderedDict[Any, Any],
        key: Hashable,
        make: Callable[[], T],
        count: bool = False,
        limit: int = OBJECT_ENVIRONMENTS,
    ) -> T:
        """The value for ``key`` in ``store``, made by ``make()`` (outside the lock) when missing.

        ``store`` keeps the last ``limit`` keys used. ``count``: tally :attr:`hits` and :attr:`misses`.
        """
        with self._lock:
            if key in store:
                self.hits += count
                store.move_to_end(key)
                return store[key]
        value = make()
        with self._lock:
            if key in store:  # made meanwhile by another query: that one is kept
                return store[key]
            self.misses += count
            store[key] = value
            while len(store) > limit:
                store.popitem(last=False)
        return value
