"""Objects in an RGB-D frame: the points above the support planes, clustered (seed 004, section 3.1).

The seed detects objects in the RGB-D image and estimates the chosen one's position from depth.
Here, without a learned detector:

1. the frame's points, in the world frame (z up), are segmented into planar regions by the terrain
   code (:class:`~baseplace.terrain.segmentation.RobustSegmenter` on a height map, seed 000); the
   level regions of at least ``min_support_area`` are the support planes (the table, the floor);
2. a point belongs to the support whose plane lies highest below it, among those whose footprint
   (the convex hull of the region's cells: objects leave holes in the region, not in its hull)
   holds it; points between ``min_height`` and ``max_height`` above it are object points;
3. object points are linked by 3-D connected components of ``link``-sized voxels (26-neighbours,
   on the occupied voxels only: :func:`_voxel_components`); clusters of fewer than ``min_points`` points or wider than
   ``max_size`` (a table's side face, a person) are dropped;
4. each cluster gets its world box (its bottom extended down to the support plane: the camera sees
   the top and one side of an object, never its bottom) and its image box (the pixels of its points).

The operator's hand is left out (:func:`detect_objects`, ``hand_px``): the clusters under its
landmarks, and those within ``hand_reach`` of them that reach into the landmarks' image box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, NothingFoundError


@dataclass(frozen=True)
class ObjectSettings:
    """How objects are cut out of a frame.

    Attributes:
        resolution: height-map cell of the support segmentation [m].
        min_support_area: smallest level region that counts as a support plane [m^2].
        max_support_tilt_deg: steepest region that counts as a support plane [deg].
        min_height: points lower than this above their support [m] are its surface and its noise.
        max_height: points higher than this above their support [m] are not on it (a shelf above).
        link: voxel edge [m] of the clustering: points in touching voxels are one object.
        min_points: smaller clusters are noise.
        max_size: clusters with a horizontal side longer than this [m] are not graspable objects.
        hand_landmarks: a cluster under at least this many hand landmarks is the hand (its fingers
            may fall apart into clusters of their own).
        hand_reach: clusters closer than this [m] to the hand, in the landmarks' image box, are
            parts of it (a finger hidden behind the others: no landmark pixel shows it).
    """

    resolution: float = 0.02
    min_support_area: float = 0.1
    max_support_tilt_deg: float = 10.0
    min_height: float = 0.012
    max_height: float = 0.5
    link: float = 0.012
    min_points: int = 20
    max_size: float = 0.5
    hand_landmarks: int = 1
    hand_reach: float = 0.08

    def __post_init__(self) -> None:
        lengths = (
            self.resolution,
            self.min_support_area,
            self.min_height,
            self.max_height,
            self.link,
            self.max_size,
        )
        if not all(math.isfinite(v) and v > 0 for v in lengths) or self.min_height >= self.max_height:
            raise InputError(
                f"object settings must be positive lengths with min_height < max_height, got {self}"
            )


@dataclass(frozen=True)
class SupportPlane:
    """A level planar region objects stand on: ``z = -(d + n_x x + n_y y) / n_z`` (world frame)."""

    normal: NDArray[np.float64]
    d: float
    hull: NDArray[np.float64]
    """(K, 2) convex hull of the region's cells, counter-clockwise [m]."""

    def height_at(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Plane height z [m] above points (N, 2)."""
        n = self.normal
        return np.asarray(-(self.d + n[0] * xy[:, 0] + n[1] * xy[:, 1]) / n[2], dtype=np.float64)

    def holds(self, xy: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(N,) True for points (N, 2) inside the hull or on it (within 1e-9 m^2 of each edge's cross product)."""
        h = np.ascontiguousarray(self.hull, dtype=np.float64)
        return np.asarray(
            _inside_convex(np.ascontiguousarray(xy, dtype=np.float64), h, np.roll(h, -1, axis=0) - h)
        )


@nb.njit(cache=True)
def _inside_convex(
    xy: NDArray[np.float64], hull: NDArray[np.float64], edges: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Each point on the inner side of every counter-clockwise edge (cross >= -1e-9; NaN: outside).

    A loop that leaves a point at its first failed edge: 10 ms for 300 000 points; the numpy form
    built an (N, K, 2) array, half the objects step's time on a 640x480 frame.
    """
    out = np.zeros(len(xy), dtype=np.bool_)
    for i in range(len(xy)):
        x, y = xy[i, 0], xy[i, 1]
        inside = True
        for k in range(len(hull)):
            cross = edges[k, 0] * (y - hull[k, 1]) - edges[k, 1] * (x - hull[k, 0])
            if not cross >= -1e-9:
                inside = False
                break
        out[i] = inside
    return out


@dataclass(frozen=True)
class DetectedObject:
    """An object found in the frame.

    Attributes:
        box_world: (2, 3) min and max corner of its axis-aligned world box [m], bottom on the support.
        image_box: (2, 2) min and max corner (u, v) of its pixels [px], inclusive.
        n_points: its depth points.
        support_height: height of the support plane under its centre [m].
    """

    box_world: NDArray[np.float64]
    image_box: NDArray[np.float64]
    n_points: int
    support_height: float

    @property
    def position(self) -> NDArray[np.float64]:
        """Centre of the world box (3,) [m]."""
        return np.asarray(self.box_world.mean(axis=0), dtype=np.float64)

    @property
    def size(self) -> NDArray[np.float64]:
        """Extent of the world box (3,) [m]."""
        return np.asarray(self.box_world[1] - self.box_world[0], dtype=np.float64)

    def to_json(self) -> dict[str, Any]:
        """``position``, ``size``, ``box_world``, ``image_box``, ``n_points``, ``support_height``."""
        return {"position": np.round(self.position, 4).tolist(), "size": np.round(self.size, 4).tolist(),
                "box_world": np.round(self.box_world, 4).tolist(), "image_box": self.image_box.tolist(),
                "n_points": self.n_points, "support_height": round(self.support_height, 4)}  # fmt: skip


@dataclass(frozen=True)
class Detections:
    """What :func:`detect_objects` found.

    Attributes:
        objects: the objects, largest image box first.
        hand: (H, W) True on the pixels of the hand's clusters (the operator leaves; a planner
            should not treat the hand as an obstacle).
    """

    objects: list[DetectedObject]
    hand: NDArray[np.bool_]


class NoSupportPlaneError(NothingFoundError):
    """No level region large enough to be a table or the floor in the frame (exit 3)."""


def support_planes(points: NDArray[np.float64], settings: ObjectSettings) -> list[SupportPlane]:
    """The level planar regions of a z-up world cloud (N, 3) [m] large enough to hold objects."""
    from scipy.spatial import ConvexHull, QhullError

    from baseplace.terrain.heightmap import HeightMap
    from baseplace.terrain.pipeline import _check_grid, refine_region_planes
    from baseplace.terrain.segmentation import NoSupportError, RobustSegmenter
    from baseplace.terrain.voxels import VoxelMap

    _check_grid(points, settings.resolution)
    voxels = VoxelMap.from_points(points, min(0.025, settings.resolution))
    hmap = HeightMap.from_voxels(voxels, settings.resolution)
    try:
        seg = refine_region_planes(RobustSegmenter().segment(hmap), voxels)
    except NoSupportError:
        return []
    xs, ys = hmap.cell_centres()
    planes = []
    for region in seg.regions:
        if region.area < settings.min_support_area or region.tilt > math.radians(
            settings.max_support_tilt_deg
        ):
            continue
        cells = np.stack([xs[seg.labels == region.id], ys[seg.labels == region.id]], axis=1)
        corners = (
            cells[:, None, :] + np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]]) * settings.resolution / 2
        ).reshape(-1, 2)
        try:
            hull = corners[ConvexHull(corners).vertices]
        except QhullError:
            continue
        plane = SupportPlane(np.asarray(region.normal, dtype=float), float(region.d), hull)
        planes.append(_refit(plane, points))
    return planes


REFIT_BANDS = (0.02, 0.01) + (0.006,) * 6
"""The bands [m] around the plane whose points :func:`_refit` fits in turn. The last, 6 mm (about
1.5 sigma of the depth noise on a table 1.7 m away), is repeated until the plane settles: each pass
lets go of more of the table's front face, which the first bands take in (chosen on the pointing
experiment's development scenes, docs/protocols/pointing_v3.md: with (0.02, 0.01) alone the table
plane lay up to 1.7 cm below its near edge)."""
REFIT_SETTLED_M = 0.0005
"""The refit stops when the plane moves less than this [m] over its footprint's corners."""


@nb.njit(cache=True)
def _band_moments(
    xyz: NDArray[np.float64], normal: NDArray[np.float64], d: float, band: float
) -> NDArray[np.float64]:
    """(n, sums of x, y, z, xx, xy, yy, xz, yz) of the points (N, 3) within ``band`` [m] (vertically) of a plane.

    One loop without temporaries: the refit's narrowing passes over a floor's 200 000 points cost
    less than one least-squares solve did.
    """
    out = np.zeros(9)
    for i in range(len(xyz)):
        x, y, z = xyz[i, 0], xyz[i, 1], xyz[i, 2]
        if abs(z + (d + normal[0] * x + normal[1] * y) / normal[2]) < band:
            out[0] += 1.0
            out[1] += x
            out[2] += y
            out[3] += z
            out[4] += x * x
            out[5] += x * y
            out[6] += y * y
            out[7] += x * z
            out[8] += y * z
    return out


def _level_plane_fit(m: NDArray[np.float64], hull: NDArray[np.float64]) -> SupportPlane:
    """The plane z = a x + b y + c of least squares from :func:`_band_moments`' sums (n >= 3), centred."""
    n, sx, sy, sz, sxx, sxy, syy, sxz, syz = m
    mx, my, mz = sx / n, sy / n, sz / n
    cov = np.array([[sxx - n * mx * mx, sxy - n * mx * my], [sxy - n * mx * my, syy - n * my * my]])
    a, b = np.linalg.lstsq(cov, np.array([sxz - n * mx * mz, syz - n * my * mz]), rcond=None)[0]
    c = mz - a * mx - b * my
    normal = np.array([-a, -b, 1.0])
    norm = float(np.linalg.norm(normal))
    return SupportPlane(normal / norm, -c / norm, hull)


def _refit(plane: SupportPlane, points: NDArray[np.float64]) -> SupportPlane:
    """The plane fitted by least squares to the points within each of :data:`REFIT_BANDS` of it, over its hull.

    The terrain's plane is fitted to its voxels within 10 cm of the region, which takes in the
    bottoms of the objects standing on it and tilts it by a degree or more. A band of 2 cm still
    holds the top of the table's front face, which the camera sees below the near edge: it tilts
    the plane down there by a centimetre, and the near edge's top then lies above ``min_height``
    and links the objects beside it into one cluster; narrower bands, repeated, let go of it.
    """
    inside = np.ascontiguousarray(points[plane.holds(points[:, :2])], dtype=np.float64)
    for k, band in enumerate(REFIT_BANDS):
        moments = _band_moments(inside, np.ascontiguousarray(plane.normal, dtype=np.float64), plane.d, band)
        if moments[0] < 3:
            return plane
        fitted = _level_plane_fit(moments, plane.hull)
        moved = float(np.max(np.abs(fitted.height_at(plane.hull) - plane.height_at(plane.hull))))
        plane = fitted
        if k >= 2 and moved < REFIT_SETTLED_M:
            break
    return plane


def _heights_above_support(
    xyz: NDArray[np.float64], planes: list[SupportPlane], below: float
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each point's height above the highest support plane under it (inf: none) and that plane's index."""
    best = np.full(len(xyz), np.inf)
    which = np.full(len(xyz), -1, dtype=np.int64)
    for k, plane in enumerate(planes):
        h = xyz[:, 2] - plane.height_at(xyz[:, :2])
        better = plane.holds(xyz[:, :2]) & (h > -below) & (h < best)
        best[better], which[better] = h[better], k
    return best, which


def detect_objects(
    points_world: ArrayLike, settings: ObjectSettings | None = None, hand_px: ArrayLike | None = None
) -> Detections:
    """The objects standing on the support planes of an organised world cloud, and the hand's pixels.

    Args:
        points_world: (H, W, 3) the frame's points in the world frame (z up) [m], NaN without depth.
        settings: how objects are cut out (None: defaults).
        hand_px: (21, 2) the hand's landmark pixels (u, v); the cluster holding them is left out.

    Returns:
        The objects (largest image box first) and the hand's pixels.

    Raises:
        NoSupportPlaneError: no level region of ``min_support_area`` in the frame.
    """
    s = settings or ObjectSettings()
    P = np.asarray(points_world, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(f"points_world must be (H, W, 3), got {P.shape}")
    height, width = P.shape[:2]
    valid = np.all(np.isfinite(P), axis=2)
    flat = P[valid]
    if len(flat) == 0:
        raise NoSupportPlaneError("the depth image has no valid pixel")
    planes = support_planes(flat, s)
    if not planes:
        raise NoSupportPlaneError(
            f"no support plane (a level region of {s.min_support_area} m^2 or more: a table, the floor) in the depth image"
        )
    h, which = _heights_above_support(flat, planes, s.min_height)
    on = (h >= s.min_height) & (h <= s.max_height)
    pix = np.argwhere(valid)[on]  # (n, 2) row, col
    xyz, support = flat[on], which[on]
    if len(xyz) == 0:
        return Detections([], np.zeros((height, width), dtype=bool))
    point_label, n = _voxel_components(np.floor(xyz / s.link).astype(np.int64))
    label_image = np.full((height, width), -1, dtype=np.int64)
    label_image[pix[:, 0], pix[:, 1]] = point_label
    hand = _hand_labels(label_image, hand_px, s.hand_landmarks)
    hand |= _near(xyz, pix, point_label, hand, hand_px, s.hand_reach)
    objects = []
    for k in range(n):
        mine = point_label == k
        if mine.sum() < s.min_points or k in hand:
            continue
        p = xyz[mine]
        lo_w, hi_w = p.min(axis=0), p.max(axis=0)
        if max(hi_w[0] - lo_w[0], hi_w[1] - lo_w[1]) > s.max_size:
            continue
        centre = (lo_w[:2] + hi_w[:2]) / 2
        plane = planes[int(np.bincount(support[mine]).argmax())]
        ground = float(plane.height_at(centre[None])[0])
        lo_w = np.r_[lo_w[:2], min(lo_w[2], ground)]
        rc = pix[mine]
        image_box = np.array(
            [[rc[:, 1].min(), rc[:, 0].min()], [rc[:, 1].max(), rc[:, 0].max()]], dtype=float
        )
        objects.append(DetectedObject(np.stack([lo_w, hi_w]), image_box, int(mine.sum()), ground))
    objects.sort(key=lambda o: -float(np.prod(o.image_box[1] - o.image_box[0] + 1)))
    return Detections(objects, np.isin(label_image, sorted(hand)))


NEIGHBOURS = np.array([d for d in np.ndindex(3, 3, 3) if d > (1, 1, 1)], dtype=np.int64) - 1
"""The 13 of a voxel's 26 neighbours that come after it in C order; the other 13 see it."""


def _voxel_components(keys: NDArray[np.int64]) -> tuple[NDArray[np.int64], int]:
    """The 26-connected components of the voxels (N, 3) of the points, numbered as ``ndimage.label``.

    ``ndimage.label`` on the dense grid of the points' bounding box numbers them in C order of their
    first voxel; this does the same on the occupied voxels only (a sorted array of their flat
    indices and a sparse graph), so the frame's extent costs no memory: the grid of a frame whose
    object points reach from the hand to the floor's far edge held millions of voxels. The flat
    indices fit int64: object points lie over the support planes' hulls, inside the height map that
    ``support_planes`` checked against the memory cap, and within ``max_height`` above them.

    Returns:
        (N,) each point's component (0 ... n-1) and n.
    """
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    lo = keys.min(axis=0) - 1  # a margin: the neighbours of every voxel have valid flat indices
    shape = keys.max(axis=0) - lo + 2
    flat = np.ravel_multi_index(tuple((keys - lo).T), tuple(int(v) for v in shape))
    voxels, of_point = np.unique(flat, return_inverse=True)
    cells = np.stack(np.unravel_index(voxels, tuple(int(v) for v in shape)), axis=1)
    rows, cols = [], []
    for d in NEIGHBOURS:
        other = np.ravel_multi_index(tuple((cells + d).T), tuple(int(v) for v in shape))
        at = np.minimum(np.searchsorted(voxels, other), len(voxels) - 1)
        hit = voxels[at] == other
        rows.append(np.flatnonzero(hit))
        cols.append(at[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_array((np.ones(len(r), dtype=np.int8), (r, c)), shape=(len(voxels), len(voxels)))
    n, component = connected_components(graph, directed=False)
    _, first = np.unique(component, return_index=True)  # each component's first voxel in C order
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(n)
    return rank[component][of_point.ravel()], int(n)


def _near(xyz: NDArray[np.float64], pix: NDArray[np.int64], point_label: NDArray[np.int64], hand: set[int],
          hand_px: ArrayLike | None, reach: float) -> set[int]:  # fmt: skip
    """Clusters within ``reach`` [m] of the hand's whose pixels meet the landmarks' bounding box.

    The box is grown by 5 px. These are parts of the hand that no landmark lands on, such as a
    pointing finger hidden behind the curled ones; repeated for parts of parts.
    """
    from scipy.spatial import cKDTree

    if not hand or hand_px is None:
        return set()
    px = np.asarray(hand_px, dtype=float).reshape(-1, 2)
    lo, hi = np.nanmin(px, axis=0) - 5, np.nanmax(px, axis=0) + 5
    uv = pix[:, ::-1]
    in_box = np.all((uv >= lo) & (uv <= hi), axis=1)
    candidates = set(np.unique(point_label[in_box]).tolist()) - hand
    found, todo = set(hand), set(hand)
    while todo and candidates - found:
        tree = cKDTree(xyz[np.isin(point_label, sorted(todo))])
        others = np.isin(point_label, sorted(candidates - found))
        distance, _ = tree.query(xyz[others], distance_upper_bound=reach)
        todo = set(np.unique(point_label[others][np.isfinite(distance)]).tolist())
        found |= todo
    return found - hand


def _hand_labels(label_image: NDArray[np.int64], hand_px: ArrayLike | None, needed: int) -> set[int]:
    """Clusters under at least ``needed`` landmarks.

    Each landmark counts for the cluster at its pixel, else the most common one within 1 px: a
    landmark lies on the hand, so the depth there is the hand's.
    """
    if hand_px is None:
        return set()
    counts: dict[int, int] = {}
    for u, v in np.asarray(hand_px, dtype=float).reshape(-1, 2):
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        r, c = round(v), round(u)
        window = label_image[max(r - 1, 0) : max(r + 2, 0), max(c - 1, 0) : max(c + 2, 0)]
        inside = 0 <= r < label_image.shape[0] and 0 <= c < label_image.shape[1]
        k = int(label_image[r, c]) if inside else -1
        if k < 0 and (window >= 0).any():
            k = int(np.bincount(window[window >= 0]).argmax())
        if k >= 0:
            counts[k] = counts.get(k, 0) + 1
    return {k for k, c in counts.items() if c >= needed}


__all__ = [
    "DetectedObject",
    "NoSupportPlaneError",
    "ObjectSettings",
    "SupportPlane",
    "detect_objects",
    "support_planes",
]
