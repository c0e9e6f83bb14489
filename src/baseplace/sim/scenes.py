"""Random test scenes with exact ground truth (seed 000, section VI-A).

A scene is a floor, ``n_planes`` inclined planes of one size class, and a box of small objects.
Every piece is analytic, so the height, the owning plane and the normal at any (x, y) are exact:

* A :class:`Plane` is a solid block: a rectangular footprint in xy, a planar top surface
  ``z = a x + b y + c`` over it, and vertical side walls down to the floor. The floor is plane 0.
* Half the inclined planes (the extra one when odd) are *ramps*: the uphill direction is one of
  the footprint's axes and the low edge lies on the floor, so a robot can drive up. The rest are
  *platforms*: tilted about a uniformly random horizontal axis, lowest corner 0.1-0.3 m up.
* The :class:`Box` is an open container standing on the floor; its :class:`SceneObject` cubes
  and cylinders rest on its bottom. Box and objects are not support planes (surface id -1).

World frame, z up, metres; the scene covers ``extent`` centred at the origin.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, unknown
from baseplace.files import atomic_write
from baseplace.geometry.poses import FloatArray

SIZE_CLASSES = {"small": (1.0, 1.5), "medium": (1.5, 2.0), "large": (2.0, 2.5)}
"""Side lengths [m] of the inclined planes' footprints per size class (seed 000, VI-A)."""
PLANE_KINDS = ("floor", "ramp", "platform")
OBJECT_SHAPES = ("cube", "cylinder")
NONPLANAR = -1
"""Surface id where the top-most surface is the box or an object."""
OUTSIDE = -2
"""Surface id outside the scene extent."""
MAX_TOP = 0.8
BOX_SIZE = (0.6, 0.4, 0.3)
BOX_WALL = 0.02
OBJECT_SIZE = (0.04, 0.10)
OBJECT_COUNT = (3, 6)
LAYOUT_ATTEMPTS = 20
PLACE_TRIES = 200
MAX_CLOUD_POINTS = 100_000_000
FORMAT = "baseplace.scene"
VERSION = 1


@dataclass(frozen=True)
class SceneSettings:
    """What kind of scene to generate.

    Attributes:
        size_class: footprint side lengths of the inclined planes: "small" (1.0-1.5 m),
            "medium" (1.5-2.0 m) or "large" (2.0-2.5 m); both sides are drawn from the class.
        n_planes: number of inclined planes besides the floor (seed 000 uses 2 and 4).
        extent: scene size (x, y) [m], centred at the origin.
        tilt_deg: range of plane inclinations [deg], drawn uniformly.
        sigma: standard deviation [m] of the Gaussian noise added to cloud z (seed 000: 25 mm).
        spacing: cloud sampling distance [m] on surfaces and walls.
        with_box: add the box of objects.
        box_elevation: height of a solid pedestal under the box [m] (0: on the floor).
        box_height: outer height of the box [m] (default 0.3).
        object_height: range [m] of the objects' heights; None: cubes are cubes and cylinders are
            4-10 cm tall. Given, every object's height is drawn from it (cubes become square
            prisms): tall objects leave room under a hand whose open fingers reach past the grasp.
        box_near: the box stands at most this far [m] from an inclined plane (None: anywhere),
            so that the planes crowd the places to stand and grasp from.
        platform_height: range [m] of the lowest corner of a raised (non-ramp) plane.
        clearance: smallest xy gap [m] between footprints, and between a footprint and the
            scene border.
    """

    size_class: str = "small"
    n_planes: int = 2
    extent: tuple[float, float] = (10.0, 10.0)
    tilt_deg: tuple[float, float] = (5.0, 15.0)
    sigma: float = 0.025
    spacing: float = 0.0125
    with_box: bool = True
    box_elevation: float = 0.0
    box_height: float = BOX_SIZE[2]
    object_height: tuple[float, float] | None = None
    box_near: float | None = None
    platform_height: tuple[float, float] = (0.1, 0.3)
    clearance: float = 0.1

    def __post_init__(self) -> None:
        if self.size_class not in SIZE_CLASSES:
            raise unknown("size class", self.size_class, SIZE_CLASSES)
        if isinstance(self.n_planes, bool) or not isinstance(self.n_planes, int) or self.n_planes < 0:
            raise InputError(f"n_planes must be a non-negative integer, got {self.n_planes!r}")
        # Lists (from JSON or a CLI) become tuples so that settings compare and hash as values.
        for name in ("extent", "tilt_deg", "platform_height"):
            object.__setattr__(self, name, _pair(getattr(self, name), name))
        if min(self.extent) <= 0:
            raise InputError(f"extent must be positive (x, y) in metres, got {self.extent}")
        if not (0.0 <= self.box_elevation <= 2.0):
            raise InputError(f"box_elevation must be between 0 and 2 m, got {self.box_elevation}")
        if not (0.05 <= self.box_height <= 1.0):
            raise InputError(f"box_height must be between 0.05 and 1 m, got {self.box_height}")
        if self.box_near is not None and not (
            math.isfinite(self.box_near) and self.box_near >= self.clearance
        ):
            raise InputError(
                f"box_near must be a distance >= clearance ({self.clearance} m), got {self.box_near}"
            )
        if self.object_height is not None:
            object.__setattr__(self, "object_height", _pair(self.object_height, "object_height"))
            lo, hi = self.object_height
            if not 0.01 <= lo <= hi <= 1.0:
                raise InputError(
                    f"object_height must be 0.01 <= low <= high <= 1 m, got {self.object_height}"
                )
        lo, hi = self.tilt_deg
        if not 0.0 <= lo <= hi < 60.0:
            raise InputError(f"tilt_deg must be a range 0 <= low <= high < 60 degrees, got {self.tilt_deg}")
        lo, hi = self.platform_height
        if not 0.0 < lo <= hi < MAX_TOP:
            raise InputError(
                f"platform_height must be 0 < low <= high < {MAX_TOP} m, got {self.platform_height}"
            )
        if not (math.isfinite(self.sigma) and self.sigma >= 0):
            raise InputError(f"sigma must be a non-negative distance in metres, got {self.sigma}")
        if not (math.isfinite(self.spacing) and self.spacing > 0):
            raise InputError(f"spacing must be a positive distance in metres, got {self.spacing}")
        if not (math.isfinite(self.clearance) and self.clearance >= 0):
            raise InputError(f"clearance must be a non-negative distance in metres, got {self.clearance}")


def _floats(value: Any, n: int, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise InputError(f"{what} must be {n} finite numbers, got {value!r}")
    return out


def _pair(value: Any, what: str) -> tuple[float, float]:
    x, y = _floats(value, 2, what)
    return (x, y)


def _triple(value: Any, what: str) -> tuple[float, float, float]:
    x, y, z = _floats(value, 3, what)
    return (x, y, z)


def _as_xy(xy: ArrayLike) -> FloatArray:
    p = np.asarray(xy, dtype=float)
    if p.shape[-1:] != (2,):
        raise InputError(f"xy points must have shape (N, 2), got {p.shape}")
    return p.reshape(-1, 2)


def _to_local(xy: FloatArray, center: tuple[float, ...], yaw: float) -> FloatArray:
    """Points (N, 2) in the frame centred at ``center`` and rotated by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = xy[:, 0] - center[0], xy[:, 1] - center[1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


def _rectangle(center: tuple[float, ...], size: tuple[float, ...], yaw: float) -> FloatArray:
    """Corners (4, 2) of a rotated rectangle, counter-clockwise."""
    hx, hy = size[0] / 2, size[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(center[:2])


def _in_rectangle(
    xy: FloatArray, center: tuple[float, ...], size: tuple[float, ...], yaw: float
) -> NDArray[np.bool_]:
    local = _to_local(xy, center, yaw)
    return (np.abs(local[:, 0]) <= size[0] / 2) & (np.abs(local[:, 1]) <= size[1] / 2)


@dataclass(frozen=True)
class Plane:
    """A solid block with a planar top: footprint rectangle in xy, top ``z = a x + b y + c``.

    Attributes:
        id: surface id; 0 is the floor, inclined planes are 1..k.
        kind: "floor", "ramp" (low edge on the floor) or "platform" (raised, tilted).
        center: footprint centre (x, y) [m], world frame.
        size: footprint side lengths (length along the yawed x axis, width) [m].
        yaw: footprint rotation about world z [rad].
        a: top surface slope dz/dx.
        b: top surface slope dz/dy.
        c: top surface height at x = y = 0 [m].
    """

    id: int
    kind: str
    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float
    a: float
    b: float
    c: float

    @property
    def normal(self) -> FloatArray:
        """Unit normal (3,) of the top surface, pointing up."""
        n = np.array([-self.a, -self.b, 1.0])
        return n / np.linalg.norm(n)

    @property
    def d(self) -> float:
        """Offset [m] of the Hessian form ``normal . p + d = 0``."""
        return float(-self.c / math.sqrt(self.a**2 + self.b**2 + 1.0))

    @property
    def tilt(self) -> float:
        """Angle [rad] between the top surface normal and world z."""
        return math.atan(math.hypot(self.a, self.b))

    @property
    def polygon(self) -> FloatArray:
        """Footprint corners (4, 2) in xy [m], counter-clockwise."""
        return _rectangle(self.center, self.size, self.yaw)

    def z(self, xy: ArrayLike) -> FloatArray:
        """Top surface height (N,) [m] of the infinite plane above xy points (N, 2)."""
        p = _as_xy(xy)
        return self.a * p[:, 0] + self.b * p[:, 1] + self.c

    def contains(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether xy points (N, 2) lie in the footprint (boundary included); shape (N,)."""
        return _in_rectangle(_as_xy(xy), self.center, self.size, self.yaw)


@dataclass(frozen=True)
class Box:
    """An open box on the floor, or on a solid pedestal; its bottom is as thick as its walls.

    Attributes:
        center: footprint centre (x, y) [m], world frame.
        yaw: rotation about world z [rad].
        size: outer (length, width, height) [m].
        wall: wall and bottom thickness [m].
        elevation: height of the pedestal the box stands on [m] (0: on the floor).
    """

    center: tuple[float, float]
    yaw: float
    size: tuple[float, float, float] = BOX_SIZE
    wall: float = BOX_WALL
    elevation: float = 0.0

    @property
    def inner_size(self) -> tuple[float, float]:
        """Inner (length, width) [m]."""
        return (self.size[0] - 2 * self.wall, self.size[1] - 2 * self.wall)

    @property
    def polygon(self) -> FloatArray:
        """Outer footprint corners (4, 2) [m], counter-clockwise."""
        return _rectangle(self.center, self.size, self.yaw)

    @property
    def inner_polygon(self) -> FloatArray:
        """Inner footprint corners (4, 2) [m], counter-clockwise."""
        return _rectangle(self.center, self.inner_size, self.yaw)

    def contains(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether xy points (N, 2) lie in the outer footprint; shape (N,)."""
        return _in_rectangle(_as_xy(xy), self.center, self.size, self.yaw)

    def top(self, xy: ArrayLike) -> FloatArray:
        """Top of the box material (N,) [m]: the rim height on the walls, the bottom inside."""
        inner = _in_rectangle(_as_xy(xy), self.center, self.inner_size, self.yaw)
        return self.elevation + np.where(inner, self.wall, self.size[2])


@dataclass(frozen=True)
class SceneObject:
    """A cube or upright cylinder resting on the box bottom (a grasp target).

    Attributes:
        shape: "cube" (size = edge lengths) or "cylinder" (size = (diameter, diameter, height)).
        center: centroid (x, y, z) [m], world frame.
        yaw: rotation about world z [rad].
        size: extents along the object's x, y and z axes [m].
    """

    shape: str
    center: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]

    @property
    def bottom(self) -> float:
        """Height [m] of the object's bottom face."""
        return self.center[2] - self.size[2] / 2

    @property
    def top(self) -> float:
        """Height [m] of the object's top face."""
        return self.center[2] + self.size[2] / 2

    @property
    def radius(self) -> float:
        """Radius [m] of the xy circle enclosing the footprint."""
        return math.hypot(self.size[0], self.size[1]) / 2 if self.shape == "cube" else self.size[0] / 2

    def contains(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether xy points (N, 2) lie in the footprint; shape (N,)."""
        p = _as_xy(xy)
        if self.shape == "cube":
            return _in_rectangle(p, self.center, self.size, self.yaw)
        return np.hypot(p[:, 0] - self.center[0], p[:, 1] - self.center[1]) <= self.size[0] / 2


@dataclass(frozen=True)
class Scene:
    """A generated scene: the floor and inclined planes, the box and its objects.

    Attributes:
        settings: the settings it was generated with.
        planes: the floor and the inclined planes; ``planes[k].id == k``.
        box: the box, or None.
        objects: the objects in the box.
    """

    settings: SceneSettings
    planes: tuple[Plane, ...]
    box: Box | None = None
    objects: tuple[SceneObject, ...] = field(default=())

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Scene extent (x_min, y_min, x_max, y_max) [m]."""
        ex, ey = self.settings.extent
        return (-ex / 2, -ey / 2, ex / 2, ey / 2)

    def _layers(self, xy: FloatArray) -> Iterator[tuple[int, NDArray[np.bool_], FloatArray]]:
        """(surface id, footprint mask, top heights over the mask) of every piece, bottom up."""
        for plane in self.planes:
            mask = plane.contains(xy)
            yield plane.id, mask, plane.z(xy[mask])
        if self.box is not None:
            mask = self.box.contains(xy)
            yield NONPLANAR, mask, self.box.top(xy[mask])
        for obj in self.objects:
            mask = obj.contains(xy)
            yield NONPLANAR, mask, np.full(int(mask.sum()), obj.top)

    def _top(self, xy: ArrayLike) -> tuple[FloatArray, NDArray[np.int64]]:
        p = _as_xy(xy)
        height = np.full(len(p), -np.inf)
        ids = np.full(len(p), OUTSIDE, dtype=np.int64)
        for sid, mask, z in self._layers(p):
            idx = np.flatnonzero(mask)
            # Ties go to the later piece: on a ramp's low edge the ramp, not the floor, is on top.
            higher = z >= height[idx]
            height[idx[higher]] = z[higher]
            ids[idx[higher]] = sid
        height[ids == OUTSIDE] = np.nan
        return height, ids

    def height(self, xy: ArrayLike) -> FloatArray:
        """Height (N,) [m] of the top-most surface above xy points (N, 2); NaN outside the scene."""
        return self._top(xy)[0]

    def surface_id(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Id (N,) of the plane whose top is top-most above xy points (N, 2).

        Returns:
            (N,) int: 0 the floor, 1..k an inclined plane, :data:`NONPLANAR` (-1) the box or an
            object, :data:`OUTSIDE` (-2) beyond the scene extent.
        """
        return self._top(xy)[1]

    def sample_cloud(
        self, rng: np.random.Generator, spacing: float | None = None, sigma: float | None = None
    ) -> FloatArray:
        """A point cloud of the scene as seen from above, with noise on z.

        Points lie on the top-most surfaces (one per cell of a grid with the given spacing,
        uniformly jittered in the cell) and on the vertical walls of the planes, the box (outside
        and inside) and the objects, at the same spacing.

        Args:
            rng: random generator.
            spacing: sampling distance [m]; the settings' spacing if None.
            sigma: std [m] of Gaussian noise added to z only; the settings' sigma if None.

        Returns:
            (N, 3) points [m], world frame; a 10 m x 10 m scene at 12.5 mm has ~650k points.
        """
        spacing = self.settings.spacing if spacing is None else float(spacing)
        sigma = self.settings.sigma if sigma is None else float(sigma)
        if not (math.isfinite(spacing) and spacing > 0):
            raise InputError(f"spacing must be a positive distance in metres, got {spacing}")
        if not (math.isfinite(sigma) and sigma >= 0):
            raise InputError(f"sigma must be a non-negative distance in metres, got {sigma}")
        x0, y0, x1, y1 = self.bounds
        nx, ny = math.ceil((x1 - x0) / spacing), math.ceil((y1 - y0) / spacing)
        if nx * ny > MAX_CLOUD_POINTS:
            raise InputError(f"spacing {spacing} m gives {nx * ny:.2e} points (limit {MAX_CLOUD_POINTS:.0e})")
        x = x0 + (np.arange(nx)[None, :] + rng.random((ny, nx))) * ((x1 - x0) / nx)
        y = y0 + (np.arange(ny)[:, None] + rng.random((ny, nx))) * ((y1 - y0) / ny)
        xy = np.stack([x.ravel(), y.ravel()], axis=1)
        parts = [np.column_stack([xy, self.height(xy)]), *self._wall_points(rng, spacing)]
        points = np.concatenate(parts)
        if sigma > 0:
            points[:, 2] += rng.normal(0.0, sigma, len(points))
        return points

    def _wall_points(self, rng: np.random.Generator, spacing: float) -> Iterator[FloatArray]:
        for plane in self.planes[1:]:
            yield from _polygon_walls(rng, plane.polygon, 0.0, plane.z, spacing)
        if self.box is not None:
            box = self.box

            def rim(p: FloatArray) -> FloatArray:
                return np.full(len(p), box.elevation + box.size[2])

            yield from _polygon_walls(rng, box.polygon, 0.0, rim, spacing)  # pedestal and outer walls
            yield from _polygon_walls(rng, box.inner_polygon, box.elevation + box.wall, rim, spacing)
        for obj in self.objects:
            top = obj.top

            def flat(p: FloatArray, top: float = top) -> FloatArray:
                return np.full(len(p), top)

            if obj.shape == "cube":
                corners = _rectangle(obj.center, obj.size, obj.yaw)
                yield from _polygon_walls(rng, corners, obj.bottom, flat, spacing)
            else:
                r, c = obj.size[0] / 2, np.asarray(obj.center[:2])

                def circle(u: FloatArray, r: float = r, c: FloatArray = c) -> FloatArray:
                    return c + r * np.stack([np.cos(2 * np.pi * u), np.sin(2 * np.pi * u)], axis=-1)

                yield _wall(rng, circle, 2 * np.pi * r, obj.bottom, flat, spacing)


def _wall(
    rng: np.random.Generator,
    curve: Callable[[FloatArray], FloatArray],
    length: float,
    z_bottom: float,
    z_top: Callable[[FloatArray], FloatArray],
    spacing: float,
) -> FloatArray:
    """Jittered-grid points (M, 3) on a vertical wall over ``curve(u)``, u in [0, 1), up to z_top."""
    nu = max(1, math.ceil(length / spacing))
    ends = curve(np.array([0.0, 0.5, 1.0]))
    height = float(np.max(z_top(ends))) - z_bottom  # walls here have linear or constant tops
    if height <= 0:
        return np.empty((0, 3))
    nv = math.ceil(height / spacing)
    u = (np.arange(nu)[None, :] + rng.random((nv, nu))) / nu
    z = z_bottom + (np.arange(nv)[:, None] + rng.random((nv, nu))) * (height / nv)
    xy = curve(u.ravel())
    z = z.ravel()
    keep = z <= z_top(xy)
    return np.column_stack([xy[keep], z[keep]])


def _polygon_walls(
    rng: np.random.Generator,
    corners: FloatArray,
    z_bottom: float,
    z_top: Callable[[FloatArray], FloatArray],
    spacing: float,
) -> Iterator[FloatArray]:
    for k in range(len(corners)):
        p0, p1 = corners[k], corners[(k + 1) % len(corners)]

        def edge(u: FloatArray, p0: FloatArray = p0, p1: FloatArray = p1) -> FloatArray:
            return p0 + u[:, None] * (p1 - p0)

        yield _wall(rng, edge, float(np.linalg.norm(p1 - p0)), z_bottom, z_top, spacing)


def _plane_shape(
    rng: np.random.Generator, s: SceneSettings, kind: str
) -> tuple[tuple[float, float], float, float, float, float] | None:
    """Random (size, yaw, a, b, z at the centre) of a plane centred at the origin, or None if too high."""
    lo, hi = SIZE_CLASSES[s.size_class]
    length, width = (float(v) for v in rng.uniform(lo, hi, 2))
    yaw = float(rng.uniform(-np.pi, np.pi))
    slope = math.tan(math.radians(float(rng.uniform(*s.tilt_deg))))
    if kind == "ramp":
        # Uphill along a footprint axis, so the whole low edge lies on the floor.
        k = int(rng.integers(4))
        uphill = yaw + k * np.pi / 2
        half = (length if k % 2 == 0 else width) / 2
        low = 0.0
        if 2 * half * slope > MAX_TOP:
            return None
    else:
        uphill = float(rng.uniform(-np.pi, np.pi))
        rel = uphill - yaw
        half = (abs(math.cos(rel)) * length + abs(math.sin(rel)) * width) / 2
        room = MAX_TOP - 2 * half * slope
        if room < s.platform_height[0]:
            return None
        low = float(rng.uniform(s.platform_height[0], min(s.platform_height[1], room)))
    a, b = slope * math.cos(uphill), slope * math.sin(uphill)
    return (length, width), yaw, a, b, low + half * slope


def _place(
    rng: np.random.Generator,
    s: SceneSettings,
    size: tuple[float, ...],
    yaw: float,
    placed: list[shapely.Polygon],
    within: float | None = None,
) -> tuple[float, float] | None:
    """A random centre keeping the rotated rectangle inside the scene and clear of ``placed``.

    With ``within``, the rectangle must also come that close [m] to one of ``placed``.
    """
    c, sn = abs(math.cos(yaw)), abs(math.sin(yaw))
    hx = (c * size[0] + sn * size[1]) / 2 + s.clearance
    hy = (sn * size[0] + c * size[1]) / 2 + s.clearance
    ex, ey = s.extent[0] / 2 - hx, s.extent[1] / 2 - hy
    if ex < 0 or ey < 0:
        return None
    center = (float(rng.uniform(-ex, ex)), float(rng.uniform(-ey, ey)))
    poly = shapely.Polygon(_rectangle(center, size, yaw))
    gaps = [poly.distance(other) for other in placed]
    if any(g < s.clearance for g in gaps) or (within is not None and gaps and min(gaps) > within):
        return None
    placed.append(poly)
    return center


def _objects(
    rng: np.random.Generator, box: Box, height: tuple[float, float] | None = None
) -> tuple[SceneObject, ...]:
    """3-6 cubes and cylinders resting on the box bottom, their enclosing circles apart.

    With ``height``, every object's height is drawn from that range (cubes become square prisms).
    """
    count = int(rng.integers(OBJECT_COUNT[0], OBJECT_COUNT[1] + 1))
    gap = 0.005
    for _ in range(LAYOUT_ATTEMPTS):
        objects: list[SceneObject] = []
        for _ in range(PLACE_TRIES):
            shape = OBJECT_SHAPES[int(rng.integers(2))]
            w, h = (float(v) for v in rng.uniform(*OBJECT_SIZE, 2))
            if height is not None:
                h = float(rng.uniform(*height))
            size = (w, w, w) if shape == "cube" and height is None else (w, w, h)
            yaw = float(rng.uniform(-np.pi, np.pi))
            probe = SceneObject(shape, (0.0, 0.0, 0.0), yaw, size)
            mx = box.inner_size[0] / 2 - probe.radius - gap
            my = box.inner_size[1] / 2 - probe.radius - gap
            local = np.array([[rng.uniform(-mx, mx), rng.uniform(-my, my)]])
            cb, sb = math.cos(box.yaw), math.sin(box.yaw)
            x, y = (local @ np.array([[cb, sb], [-sb, cb]]))[0] + box.center
            if any(
                math.hypot(x - o.center[0], y - o.center[1]) < probe.radius + o.radius + gap for o in objects
            ):
                continue
            objects.append(
                SceneObject(shape, (float(x), float(y), box.elevation + box.wall + size[2] / 2), yaw, size)
            )
            if len(objects) == count:
                return tuple(objects)
    raise RuntimeError("could not place the objects in the box")  # the sizes above always fit


def generate_scene(settings: SceneSettings, rng: np.random.Generator) -> Scene:
    """Generate a random scene; the same settings and generator state give the same scene.

    Planes are placed one at a time by rejection sampling; when one does not fit, the layout
    restarts, a bounded number of times.

    Args:
        settings: what to generate.
        rng: random generator.

    Returns:
        The scene.

    Raises:
        InputError: the scene is too small for the planes (or the box), or the tilt range makes
            the planes rise above 0.8 m.
    """
    s = settings
    ex, ey = s.extent
    floor = Plane(0, "floor", (0.0, 0.0), (ex, ey), 0.0, 0.0, 0.0, 0.0)
    n_ramps = (s.n_planes + 1) // 2
    kinds = [str(k) for k in rng.permutation(["ramp"] * n_ramps + ["platform"] * (s.n_planes - n_ramps))]
    box_failed = False
    for _ in range(LAYOUT_ATTEMPTS):
        placed: list[shapely.Polygon] = []
        planes = [floor]
        for pid, kind in enumerate(kinds, start=1):
            shapes = 0
            for _ in range(PLACE_TRIES):
                shape = _plane_shape(rng, s, kind)
                if shape is None:
                    continue
                shapes += 1
                size, yaw, a, b, z_center = shape
                center = _place(rng, s, size, yaw, placed)
                if center is not None:
                    c = z_center - a * center[0] - b * center[1]
                    planes.append(Plane(pid, kind, center, size, yaw, a, b, c))
                    break
            else:
                if shapes == 0:
                    raise InputError(
                        f"tilt_deg {s.tilt_deg} is too steep for {s.size_class} planes: their tops "
                        f"would rise above {MAX_TOP} m; lower the tilt or use smaller planes"
                    )
                break
        if len(planes) <= s.n_planes:
            continue
        if not s.with_box:
            return Scene(s, tuple(planes))
        for _ in range(PLACE_TRIES):
            yaw = float(rng.uniform(-np.pi, np.pi))
            center = _place(rng, s, BOX_SIZE, yaw, placed, s.box_near)
            if center is not None:
                box = Box(
                    center, yaw, size=(BOX_SIZE[0], BOX_SIZE[1], s.box_height), elevation=s.box_elevation
                )
                return Scene(s, tuple(planes), box, _objects(rng, box, s.object_height))
        box_failed = True
    lo, hi = SIZE_CLASSES[s.size_class]
    planes_text = f"{s.n_planes} {s.size_class} planes ({lo:g}-{hi:g} m sides, {s.clearance:g} m apart)"
    what = (
        f"the {BOX_SIZE[0]:g} m x {BOX_SIZE[1]:g} m box beside {planes_text}" if box_failed else planes_text
    )
    raise InputError(
        f"scene of {ex:g} m x {ey:g} m is too small for {what}; "
        "use a larger extent, fewer planes or a smaller size class"
    )


def truth_grid(
    scene: Scene, origin_xy: ArrayLike, resolution: float, shape: tuple[int, int]
) -> tuple[NDArray[np.int64], FloatArray]:
    """Ground-truth surface ids and normals at the centres of a grid's cells.

    Cell (i, j) has its centre at ``origin_xy + ((j + 0.5) * resolution, (i + 0.5) * resolution)``:
    rows run along y, columns along x.

    Args:
        scene: the scene.
        origin_xy: (2,) corner [m] of cell (0, 0), world frame.
        resolution: cell size [m].
        shape: (H, W) cells.

    Returns:
        surface_ids: (H, W) int as :meth:`Scene.surface_id` (-1 box/object, -2 outside).
        normals: (H, W, 3) unit upward normals of the surface; NaN where the id is negative.
    """
    origin = _floats(np.asarray(origin_xy, dtype=float).ravel(), 2, "origin_xy")
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(f"resolution must be a positive distance in metres, got {resolution}")
    if len(shape) != 2 or min(shape) < 1:
        raise InputError(f"shape must be (H, W) positive cell counts, got {shape}")
    rows, cols = int(shape[0]), int(shape[1])
    x = origin[0] + (np.arange(cols) + 0.5) * resolution
    y = origin[1] + (np.arange(rows) + 0.5) * resolution
    X, Y = np.meshgrid(x, y)
    ids = scene.surface_id(np.stack([X.ravel(), Y.ravel()], axis=1))
    table = np.vstack([np.full((1, 3), np.nan), [p.normal for p in scene.planes]])
    normals = table[np.where(ids >= 0, ids + 1, 0)]
    return ids.reshape(rows, cols), normals.reshape(rows, cols, 3)


def save_scene(scene: Scene, truth_path: str | Path) -> None:
    """Write the scene's ground truth as JSON, atomically.

    Planes carry their kind, footprint (center, size, yaw, polygon), ``a, b, c`` of the top
    ``z = a x + b y + c`` and the Hessian form (normal, d); center, size, yaw and a, b, c are the
    authoritative fields, the rest are for readers. Floats are written exactly.

    Args:
        scene: the scene.
        truth_path: the JSON file to write.
    """
    planes = [
        {
            **asdict(p),
            "normal": p.normal.tolist(),
            "d": p.d,
            "polygon": p.polygon.tolist(),
            "tilt_deg": math.degrees(p.tilt),
        }
        for p in scene.planes
    ]
    box = None if scene.box is None else {**asdict(scene.box), "polygon": scene.box.polygon.tolist()}
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "settings": asdict(scene.settings),
        "extent": list(scene.settings.extent),
        "bounds": list(scene.bounds),
        "planes": planes,
        "box": box,
        "objects": [asdict(o) for o in scene.objects],
    }
    with atomic_write(truth_path, "ground truth") as tmp:
        tmp.write_text(json.dumps(doc, indent=1))


def _get(obj: Any, key: str, where: str) -> Any:
    if not isinstance(obj, dict) or key not in obj:
        raise InputError(f"scene truth file: {where} has no field {key!r}")
    return obj[key]


def _list(obj: Any, key: str) -> list[Any]:
    value = _get(obj, key, "the file")
    if not isinstance(value, list):
        raise InputError(f"scene truth file: {key!r} must be a list, got {type(value).__name__}")
    return value


def _number(obj: Any, key: str, where: str) -> float:
    return _floats([_get(obj, key, where)], 1, f"{where}.{key}")[0]


def load_scene(truth_path: str | Path) -> Scene:
    """Read a scene written by :func:`save_scene`.

    Args:
        truth_path: the JSON ground-truth file.

    Returns:
        The scene, equal to the one saved.

    Raises:
        InputError: the file is missing, not JSON, or a field is missing or malformed.
    """
    path = Path(truth_path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"scene truth file {str(path)!r} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"scene truth file {str(path)!r} is not readable JSON: {e}") from None
    if _get(doc, "format", "the file") != FORMAT or _get(doc, "version", "the file") != VERSION:
        raise InputError(f"{str(path)!r} is not a {FORMAT} file of version {VERSION}")
    raw = _get(doc, "settings", "the file")
    try:
        settings = SceneSettings(**raw)
    except TypeError as e:
        raise InputError(f"scene truth file: bad settings: {e}") from None
    planes = []
    for k, p in enumerate(_list(doc, "planes")):
        where = f"planes[{k}]"
        kind = _get(p, "kind", where)
        if kind not in PLANE_KINDS:
            raise unknown("plane kind", str(kind), PLANE_KINDS, where)
        if _get(p, "id", where) != k:
            raise InputError(f"scene truth file: {where} has id {p['id']!r}, expected {k}")
        a, b, c, yaw = (_number(p, name, where) for name in ("a", "b", "c", "yaw"))
        center = _pair(_get(p, "center", where), f"{where}.center")
        size = _pair(_get(p, "size", where), f"{where}.size")
        planes.append(Plane(k, kind, center, size, yaw, a, b, c))
    if not planes or planes[0].kind != "floor":
        raise InputError("scene truth file: planes[0] must be the floor")
    box = None
    if (raw_box := _get(doc, "box", "the file")) is not None:
        box = Box(
            _pair(_get(raw_box, "center", "box"), "box.center"),
            _number(raw_box, "yaw", "box"),
            _triple(_get(raw_box, "size", "box"), "box.size"),
            _number(raw_box, "wall", "box"),
            _number(raw_box, "elevation", "box") if "elevation" in raw_box else 0.0,
        )
    objects = []
    for k, o in enumerate(_list(doc, "objects")):
        where = f"objects[{k}]"
        shape = _get(o, "shape", where)
        if shape not in OBJECT_SHAPES:
            raise unknown("object shape", str(shape), OBJECT_SHAPES, where)
        centroid = _triple(_get(o, "center", where), f"{where}.center")
        extents = _triple(_get(o, "size", where), f"{where}.size")
        objects.append(SceneObject(shape, centroid, _number(o, "yaw", where), extents))
    return Scene(settings, tuple(planes), box, tuple(objects))
