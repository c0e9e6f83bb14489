"""Planar region segmentation of height maps (seed 000, section IV).

Two algorithms behind one interface, :class:`Segmenter` (``segment(hmap) -> Segmentation``):

* :class:`BaselineSegmenter`: region growing on local normals (Karkowski and Bennewitz 2019, as
  summarized in seed 000 IV): a neighbour joins a region if the angle between the local normals
  is below a threshold; regions below a minimum size are non-planar.
* :class:`RobustSegmenter`: seed 000's robust version: region growing repeated with growing
  thresholds, each pass accepting only regions of a minimum size; the *extension step* into
  non-planar cells by point-to-plane distance; *merging* of neighbours with similar normals and a
  small centroid-to-plane distance; the *reassignment step* (a cell moves to a neighbouring
  region whose plane is closer); and the *connected-component cleanup* (cells outside a region's
  largest component go to the closest neighbouring region).

Local normals come from least-squares planes over a window of the smoothed height map; plane
distances use the unsmoothed heights, which keep step edges sharp. Beyond the seed, a cell only
ever moves to a region whose plane fits it (within ``extend_dist`` of its raw or smoothed height,
:func:`_fits`), so neither the reassignment nor the cleanup hands a cell to a neighbour across a
step (a corner of a ramp cut off by the platform once went to the floor 0.29 m below); where
several planes fit (a crease), the reassignment picks the closest by the smoothed height and
one-cell notches of the border are filled (:func:`_straighten`), so a path across a continuous
crease enters each region once.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Protocol

import numba as nb
import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.terrain.heightmap import FloatArray, HeightMap
from baseplace.terrain.planes import fit_region_planes, local_planes

Labels = NDArray[np.int32]


@dataclass(frozen=True)
class PlanarRegion:
    """A planar region ``r = (n, d, W)`` of seed 000 III-A.

    Attributes:
        id: region id (its label in the segmentation, 0 = largest).
        normal: (3,) unit normal pointing up.
        d: offset of the plane ``n . p + d = 0`` [m].
        centroid: (3,) mean of the region's cell points [m].
        n_cells: number of cells.
        area: horizontal area [m^2] (cells x resolution^2).
    """

    id: int
    normal: FloatArray
    d: float
    centroid: FloatArray
    n_cells: int
    area: float

    def height_at(self, xy: FloatArray) -> FloatArray:
        """Plane height z [m] above points (N, 2)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        n = self.normal
        return -(self.d + n[0] * xy[:, 0] + n[1] * xy[:, 1]) / n[2]

    @property
    def tilt(self) -> float:
        """Angle between the normal and world z [rad]."""
        return float(math.acos(min(1.0, self.normal[2])))


@dataclass(frozen=True)
class Segmentation:
    """The planar regions of a height map.

    Attributes:
        hmap: the segmented height map.
        labels: (H, W) region id per cell; -1 for non-planar or unknown cells.
        regions: the regions, ``regions[k].id == k``, largest first.
        timings_ms: time per step [ms].
    """

    hmap: HeightMap
    labels: Labels
    regions: list[PlanarRegion]
    timings_ms: dict[str, float] = field(default_factory=dict)

    def region_at(self, xy: FloatArray) -> NDArray[np.int64]:
        """Region id under points (N, 2), -1 where none."""
        row, col, inside = self.hmap.cell_of(xy)
        out = np.full(len(row), -1, dtype=np.int64)
        out[inside] = self.labels[row[inside], col[inside]]
        return out


class Segmenter(Protocol):
    """Splits a height map into planar regions and non-planar cells."""

    def segment(self, hmap: HeightMap) -> Segmentation:
        """The planar regions of ``hmap``."""
        ...


@dataclass(frozen=True)
class BaselineSettings:
    """Settings of the baseline region growing.

    Attributes:
        angle_deg: largest angle between neighbouring local normals in one region [deg].
        max_rms: largest local plane-fit residual for a cell to be planar [m].
        min_cells: smallest region; smaller ones are non-planar.
        half_window: local normals are fitted over (2 k + 1)^2 cells.
        max_tilt_deg: regions steeper than this are walls, not support: non-planar [deg].
    """

    angle_deg: float = 4.0
    max_rms: float = 0.03
    min_cells: int = 40
    half_window: int = 2
    max_tilt_deg: float = 35.0


@dataclass(frozen=True)
class RobustSettings:
    """Settings of seed 000's robust segmentation.

    Attributes:
        angles_deg: thresholds of the repeated region growing, growing [deg].
        max_rms: largest local plane-fit residual for a cell to seed or join growing [m].
        min_cells: a grown region is accepted only with at least this many cells.
        extend_dist: extension step: a non-planar neighbour joins if this close to the plane [m].
        merge_angle_deg: merge neighbours whose normals differ by less than this [deg] ...
        merge_dist: ... and whose centroids lie this close to the other plane [m]; also (an
            extension of the seed's test) merge a region into a neighbour whose plane lies within
            this distance of ``merge_share`` of its cells, which absorbs small patches whose own
            fit is tilted by a nearby step edge.
        merge_share: share of cells for the point-to-plane merge test.
        half_window: local normals are fitted over (2 k + 1)^2 cells.
        reassign_rounds: most rounds of the reassignment step.
        max_tilt_deg: regions steeper than this are walls, not support: non-planar [deg].
    """

    angles_deg: tuple[float, ...] = (1.5, 3.0, 4.5, 6.0)
    max_rms: float = 0.03
    min_cells: int = 40
    extend_dist: float = 0.05
    merge_angle_deg: float = 3.0
    merge_dist: float = 0.04
    merge_share: float = 0.9
    half_window: int = 2
    reassign_rounds: int = 20
    max_tilt_deg: float = 35.0

    def __post_init__(self) -> None:
        if not self.angles_deg or list(self.angles_deg) != sorted(self.angles_deg):
            raise InputError(f"region growing thresholds must grow, got {self.angles_deg}")


@nb.njit(cache=True)
def _grow(normals, eligible, labels, cos_thr, min_cells, order, next_label, against_mean):  # pragma: no cover
    """Region growing over 4-neighbours from seeds in ``order``; returns the next free label.

    A neighbour joins if its normal is within the threshold of the current cell's normal
    (Karkowski and Bennewitz) or, with ``against_mean``, of the region's mean normal so far, which
    cannot drift across a smooth bend from one plane into the next.
    """
    H, W = labels.shape
    queue = np.empty(H * W, dtype=np.int64)
    tried = np.zeros(H * W, dtype=np.bool_)
    for s in order:
        r0, c0 = s // W, s % W
        if labels[r0, c0] != -1 or not eligible[r0, c0] or tried[s]:
            continue
        lab = next_label
        head, tail = 0, 1
        queue[0] = s
        labels[r0, c0] = lab
        sx, sy, sz = normals[r0, c0, 0], normals[r0, c0, 1], normals[r0, c0, 2]
        while head < tail:
            cur = queue[head]
            head += 1
            r, c = cur // W, cur % W
            if against_mean:
                norm = math.sqrt(sx * sx + sy * sy + sz * sz)
                rx, ry, rz = sx / norm, sy / norm, sz / norm
            else:
                rx, ry, rz = normals[r, c, 0], normals[r, c, 1], normals[r, c, 2]
            for k in range(4):
                rr = r + (1 if k == 0 else -1 if k == 1 else 0)
                cc = c + (1 if k == 2 else -1 if k == 3 else 0)
                if rr < 0 or cc < 0 or rr >= H or cc >= W:
                    continue
                if labels[rr, cc] != -1 or not eligible[rr, cc]:
                    continue
                dot = rx * normals[rr, cc, 0] + ry * normals[rr, cc, 1] + rz * normals[rr, cc, 2]
                if dot >= cos_thr:
                    sx += normals[rr, cc, 0]
                    sy += normals[rr, cc, 1]
                    sz += normals[rr, cc, 2]
                    labels[rr, cc] = lab
                    queue[tail] = rr * W + cc
                    tail += 1
        for k in range(tail):
            tried[queue[k]] = True
        if tail < min_cells:
            for k in range(tail):
                labels[queue[k] // W, queue[k] % W] = -1
        else:
            next_label += 1
    return next_label


@nb.njit(cache=True)
def _extend(labels, heights, X, Y, normals, d, max_dist):  # pragma: no cover
    """Extension step: breadth-first from every region into unlabeled cells close to its plane."""
    H, W = labels.shape
    queue = np.empty(H * W, dtype=np.int64)
    tail = 0
    for r in range(H):
        for c in range(W):
            if labels[r, c] >= 0:
                queue[tail] = r * W + c
                tail += 1
    head = 0
    while head < tail:
        cur = queue[head]
        head += 1
        r, c = cur // W, cur % W
        lab = labels[r, c]
        n = normals[lab]
        for k in range(4):
            rr = r + (1 if k == 0 else -1 if k == 1 else 0)
            cc = c + (1 if k == 2 else -1 if k == 3 else 0)
            if rr < 0 or cc < 0 or rr >= H or cc >= W or labels[rr, cc] != -1:
                continue
            z = heights[rr, cc]
            if not np.isfinite(z):
                continue
            dist = abs(n[0] * X[rr, cc] + n[1] * Y[rr, cc] + n[2] * z + d[lab])
            if dist < max_dist:
                labels[rr, cc] = lab
                queue[tail] = rr * W + cc
                tail += 1


@nb.njit(cache=True)
def _fits(normal, d, x, y, z, zs, max_dist):  # pragma: no cover
    """Whether the plane ``normal . p + d = 0`` fits a cell: within ``max_dist`` of its height.

    Of its raw height ``z`` or of its smoothed height ``zs``: a step misses both, a noisy cell on
    the plane fits one of them.
    """
    base = normal[0] * x + normal[1] * y + d
    return abs(base + normal[2] * z) <= max_dist or abs(base + normal[2] * zs) <= max_dist


@nb.njit(cache=True)
def _reassign(labels, heights, smooth, X, Y, normals, d, max_dist):  # pragma: no cover
    """One reassignment round: a cell moves to a 4-neighbour's region whose plane is closer.

    Only a plane within ``max_dist`` of the cell's height can take it, so no cell crosses a step.
    Where several planes fit (the crease where a ramp meets the floor or a platform), the closer
    one is judged by the smoothed height: on the raw heights the noise decides each cell near the
    crease on its own and the border frays into slivers of both regions.
    """
    H, W = labels.shape
    out = labels.copy()
    changed = 0
    for r in range(H):
        for c in range(W):
            lab = labels[r, c]
            if lab < 0:
                continue
            z = heights[r, c]
            if not np.isfinite(z):
                continue
            zs = smooth[r, c] if np.isfinite(smooth[r, c]) else z
            x, y = X[r, c], Y[r, c]
            best = abs(normals[lab, 0] * x + normals[lab, 1] * y + normals[lab, 2] * zs + d[lab])
            if not _fits(normals[lab], d[lab], x, y, z, zs, max_dist):
                best = np.inf  # its own plane does not fit it either: any neighbour's that fits is better
            best_lab = lab
            for k in range(4):
                rr = r + (1 if k == 0 else -1 if k == 1 else 0)
                cc = c + (1 if k == 2 else -1 if k == 3 else 0)
                if rr < 0 or cc < 0 or rr >= H or cc >= W:
                    continue
                other = labels[rr, cc]
                if other < 0 or other == best_lab:
                    continue
                if not _fits(normals[other], d[other], x, y, z, zs, max_dist):
                    continue
                dist = abs(normals[other, 0] * x + normals[other, 1] * y + normals[other, 2] * zs + d[other])
                if dist < best:
                    best, best_lab = dist, other
            if best_lab != lab:
                out[r, c] = best_lab
                changed += 1
    return out, changed


@nb.njit(cache=True)
def _straighten(labels, heights, smooth, X, Y, normals, d, max_dist):  # pragma: no cover
    """Move every cell with 3 or 4 of its 4-neighbours in another region whose plane fits it there.

    Where two regions meet continuously (both planes fit the cells along the crease) noise leaves
    one-cell notches in the border, and a path across it enters a region twice. In place, until no
    cell moves: each move lowers the number of unlike neighbour pairs, so it ends. Returns the moves.
    """
    H, W = labels.shape
    moved = 0
    changed = True
    while changed:
        changed = False
        for r in range(H):
            for c in range(W):
                lab = labels[r, c]
                z = heights[r, c]
                if lab < 0 or not np.isfinite(z):
                    continue
                for k in range(4):  # the candidate: each neighbour's region in turn
                    rr = r + (1 if k == 0 else -1 if k == 1 else 0)
                    cc = c + (1 if k == 2 else -1 if k == 3 else 0)
                    if rr < 0 or cc < 0 or rr >= H or cc >= W:
                        continue
                    other = labels[rr, cc]
                    if other < 0 or other == lab:
                        continue
                    votes = 0
                    for m in range(4):
                        r2 = r + (1 if m == 0 else -1 if m == 1 else 0)
                        c2 = c + (1 if m == 2 else -1 if m == 3 else 0)
                        if 0 <= r2 < H and 0 <= c2 < W and labels[r2, c2] == other:
                            votes += 1
                    zs = smooth[r, c] if np.isfinite(smooth[r, c]) else z
                    if votes >= 3 and _fits(normals[other], d[other], X[r, c], Y[r, c], z, zs, max_dist):
                        labels[r, c] = other
                        moved += 1
                        changed = True
                    break
    return moved


def _seed_order(rms: FloatArray) -> NDArray[np.int64]:
    """Seeds in order of increasing local residual: the flattest cells first."""
    flat = rms.ravel()
    order = np.argsort(flat, kind="stable")
    return order[np.isfinite(flat[order])].astype(np.int64)


def _compact(labels: Labels, min_cells: int) -> tuple[Labels, int]:
    """Drop regions below ``min_cells`` and renumber the rest 0.. by decreasing size."""
    sizes = np.bincount(labels[labels >= 0].ravel()) if (labels >= 0).any() else np.zeros(0, dtype=np.int64)
    keep = np.flatnonzero(sizes >= min_cells)
    keep = keep[np.argsort(-sizes[keep], kind="stable")]
    remap = np.full(len(sizes) + 1, -1, dtype=np.int32)
    remap[keep] = np.arange(len(keep), dtype=np.int32)
    out = np.where(labels >= 0, remap[np.where(labels >= 0, labels, len(sizes))], -1).astype(np.int32)
    return out, len(keep)


def _drop_steep(hmap: HeightMap, labels: Labels, n: int, max_tilt_deg: float) -> Labels:
    """Unlabel regions steeper than ``max_tilt_deg``: step walls, not support surfaces."""
    normals, _, _, _ = fit_region_planes(hmap, labels, n)
    steep = ~(normals[:, 2] >= math.cos(math.radians(max_tilt_deg)))  # NaN planes count as steep
    if not steep.any():
        return labels
    return np.where((labels >= 0) & steep[np.maximum(labels, 0)], -1, labels).astype(np.int32)


def _regions(hmap: HeightMap, labels: Labels, n: int) -> list[PlanarRegion]:
    normals, d, centroids, counts = fit_region_planes(hmap, labels, n)
    area = hmap.resolution**2
    return [
        PlanarRegion(k, normals[k], float(d[k]), centroids[k], int(counts[k]), float(counts[k] * area))
        for k in range(n)
    ]


def _check(hmap: HeightMap) -> None:
    if not hmap.known.any():
        raise InputError("the height map has no known cells")


class NoSupportError(InputError):
    """No planar region within 30 deg of level (the pipeline explains why, from the cloud)."""


def _no_support(segmentation: Segmentation) -> Segmentation:
    if not any(r.normal[2] > math.cos(math.radians(30)) for r in segmentation.regions):
        raise NoSupportError(
            "no horizontal support surface found (no planar region is within 30 deg of level); "
            "is the cloud's up direction right? pass --transform with a 4x4 world_T_sensor file "
            'or the sensor-frame up vector, e.g. --transform "0 -1 0" for a y-down camera'
        )
    return segmentation


@dataclass(frozen=True)
class BaselineSegmenter:
    """Region growing on local normals (Karkowski and Bennewitz, summarized in seed 000 IV)."""

    settings: BaselineSettings = field(default_factory=BaselineSettings)

    def segment(self, hmap: HeightMap) -> Segmentation:
        """Grow regions once with a fixed angle threshold."""
        _check(hmap)
        s = self.settings
        t0 = time.perf_counter()
        lp = local_planes(hmap.smooth, hmap.resolution, s.half_window)
        t1 = time.perf_counter()
        labels = np.full(hmap.shape, -1, dtype=np.int32)
        eligible = lp.rms <= s.max_rms
        normals = np.nan_to_num(lp.normals)
        n = _grow(normals, eligible, labels, math.cos(math.radians(s.angle_deg)), s.min_cells,
                  _seed_order(lp.rms), 0, False)  # fmt: skip
        labels = _drop_steep(hmap, labels, n, s.max_tilt_deg)
        labels, n = _compact(labels, s.min_cells)
        regions = _regions(hmap, labels, n)
        t2 = time.perf_counter()
        timings = {"normals": (t1 - t0) * 1e3, "growing": (t2 - t1) * 1e3, "total": (t2 - t0) * 1e3}
        return _no_support(Segmentation(hmap, labels, regions, timings))


@dataclass(frozen=True)
class RobustSegmenter:
    """Seed 000's robust planar region segmentation (section IV)."""

    settings: RobustSettings = field(default_factory=RobustSettings)

    def segment(self, hmap: HeightMap) -> Segmentation:
        """Growing with growing thresholds, extension, merging, reassignment, cleanup."""
        _check(hmap)
        s = self.settings
        timings: dict[str, float] = {}
        t = time.perf_counter()

        def lap(name: str) -> None:
            nonlocal t
            now = time.perf_counter()
            timings[name] = (now - t) * 1e3
            t = now

        lp = local_planes(hmap.smooth, hmap.resolution, s.half_window)
        normals_local = np.nan_to_num(lp.normals)
        eligible = lp.rms <= s.max_rms
        order = _seed_order(lp.rms)
        lap("normals")

        labels = np.full(hmap.shape, -1, dtype=np.int32)
        n = 0
        for angle in s.angles_deg:  # over-segments first; later steps merge
            n = _grow(
                normals_local, eligible, labels, math.cos(math.radians(angle)), s.min_cells, order, n, True
            )
        labels = _drop_steep(hmap, labels, n, s.max_tilt_deg)
        lap("growing")

        X, Y = hmap.cell_centres()
        z = np.where(hmap.known, hmap.raw, np.nan)
        labels, n = self._merge(hmap, labels, n)
        normals, d, _, _ = fit_region_planes(hmap, labels, n)
        _extend(labels, z, X, Y, normals, d, s.extend_dist)
        lap("extension")

        labels, n = self._merge(hmap, labels, n)
        lap("merging")

        for _ in range(2):  # reassignment can reunite pieces of one plane: merge them, reassign again
            for _ in range(s.reassign_rounds):
                normals, d, _, _ = fit_region_planes(hmap, labels, n)
                planes = np.nan_to_num(normals), np.nan_to_num(d, nan=1e9)
                labels, changed = _reassign(labels, z, hmap.smooth, X, Y, *planes, s.extend_dist)
                if changed == 0:
                    break
            labels, n = self._merge(hmap, labels, n)
        normals, d, _, _ = fit_region_planes(hmap, labels, n)
        planes = np.nan_to_num(normals), np.nan_to_num(d, nan=1e9)
        _straighten(labels, z, hmap.smooth, X, Y, *planes, s.extend_dist)
        # A region refitted to cells that fit no other plane can tilt up into a wall: no support.
        labels = _drop_steep(hmap, labels, n, s.max_tilt_deg)
        lap("reassignment")

        labels = self._largest_components(hmap, labels, n)
        labels, n = _compact(labels, s.min_cells)
        normals, d, _, _ = fit_region_planes(hmap, labels, n)
        _extend(labels, z, X, Y, normals, d, s.extend_dist)  # cells freed by the cleanup
        regions = _regions(hmap, labels, n)
        lap("cleanup")
        timings["total"] = sum(timings.values())
        return _no_support(Segmentation(hmap, labels, regions, timings))

    def _merge(self, hmap: HeightMap, labels: Labels, n: int) -> tuple[Labels, int]:
        """Merge 4-adjacent regions with similar normals whose centroids lie near the other plane."""
        s = self.settings
        cos_thr = math.cos(math.radians(s.merge_angle_deg))
        while True:
            labels, n = _compact(labels, 1)
            if n < 2:
                return labels, n
            normals, d, centroids, counts = fit_region_planes(hmap, labels, n)
            pairs = _adjacent_pairs(labels)
            X, Y = hmap.cell_centres()
            sel = (labels >= 0) & hmap.known
            lab, pts = labels[sel], np.c_[X[sel], Y[sel], hmap.raw[sel]]
            parent = np.arange(n)
            # Star merges per round, most similar pairs first, then refit: a larger region may absorb
            # several neighbours, each tested against it, but an absorbed region takes part in nothing
            # else that round. Merging transitively would let a noisy patch chain two planes together.
            pairs = sorted(pairs, key=lambda p: -float(np.nan_to_num(normals[p[0]] @ normals[p[1]])))
            absorbed = np.zeros(n, dtype=bool)
            absorber = np.zeros(n, dtype=bool)

            merged = False
            for a, b in pairs:
                big, small = (a, b) if counts[a] >= counts[b] else (b, a)
                if absorbed[big] or absorbed[small] or absorber[small]:
                    continue
                if not np.all(np.isfinite(normals[[a, b]])):
                    continue
                seed_test = (
                    normals[a] @ normals[b] >= cos_thr
                    and abs(normals[a] @ centroids[b] + d[a]) <= s.merge_dist
                    and abs(normals[b] @ centroids[a] + d[b]) <= s.merge_dist
                )
                if not seed_test:
                    explained = False
                    for small, big in ((a, b), (b, a)):
                        own = pts[lab == small]
                        close = np.abs(own @ normals[big] + d[big]) <= s.merge_dist
                        explained |= bool(close.mean() >= s.merge_share) if len(own) else False
                    if not explained:
                        continue
                parent[small] = big
                absorbed[small] = absorber[big] = True
                merged = True
            if not merged:
                return labels, n
            roots = parent.astype(np.int32)
            labels = np.where(labels >= 0, roots[np.maximum(labels, 0)], -1).astype(np.int32)

    def _largest_components(self, hmap: HeightMap, labels: Labels, n: int) -> Labels:
        """Keep each region's largest 4-connected component; give the rest to the closest neighbour."""
        from scipy import ndimage  # here: a cached terrain never imports it (0.5 s)

        orphan = np.zeros(labels.shape, dtype=bool)
        for k in range(n):
            comp, count = ndimage.label(labels == k)
            if count > 1:
                sizes = np.bincount(comp.ravel())
                sizes[0] = 0
                orphan |= (comp > 0) & (comp != np.argmax(sizes))
        if not orphan.any():
            return labels
        labels = labels.copy()
        labels[orphan] = -1
        normals, d, _, _ = fit_region_planes(hmap, labels, n)
        X, Y = hmap.cell_centres()
        z = np.where(hmap.known, hmap.raw, np.nan)
        # Orphans join the neighbouring region whose plane is closest and fits them, spreading inward;
        # an orphan no neighbour's plane fits (a piece of a ramp cut off by a step) stays unlabelled
        # for the final extension, which only gives a cell to a region whose plane fits it.
        _extend_closest(labels, orphan, z, hmap.smooth, X, Y, np.nan_to_num(normals), np.nan_to_num(d, nan=1e9),
                        self.settings.extend_dist)  # fmt: skip
        return labels


def _adjacent_pairs(labels: Labels) -> list[tuple[int, int]]:
    pairs: set[tuple[int, int]] = set()
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        sel = (a >= 0) & (b >= 0) & (a != b)
        lo = np.minimum(a[sel], b[sel])
        hi = np.maximum(a[sel], b[sel])
        pairs.update(zip(lo.tolist(), hi.tolist(), strict=True))
    return sorted(pairs)


@nb.njit(cache=True)
def _extend_closest(labels, todo, heights, smooth, X, Y, normals, d, max_dist):  # pragma: no cover
    """Give each ``todo`` cell the region of a labelled 4-neighbour with the closest plane that fits it.

    A cell no neighbouring plane fits (see :func:`_fits`) stays unlabelled: the surface steps
    there, and the neighbour across the step is not its region. An unknown cell takes its first
    labelled neighbour.
    """
    H, W = labels.shape
    while True:
        changed = 0
        new = labels.copy()
        for r in range(H):
            for c in range(W):
                if not todo[r, c] or labels[r, c] >= 0:
                    continue
                z = heights[r, c]
                zs = smooth[r, c] if np.isfinite(smooth[r, c]) else z
                best = np.inf
                best_lab = -1
                for k in range(4):
                    rr = r + (1 if k == 0 else -1 if k == 1 else 0)
                    cc = c + (1 if k == 2 else -1 if k == 3 else 0)
                    if rr < 0 or cc < 0 or rr >= H or cc >= W:
                        continue
                    other = labels[rr, cc]
                    if other < 0:
                        continue
                    if not np.isfinite(z):
                        dist = 0.0
                    elif _fits(normals[other], d[other], X[r, c], Y[r, c], z, zs, max_dist):
                        dist = abs(normals[other, 0] * X[r, c] + normals[other, 1] * Y[r, c]
                                   + normals[other, 2] * z + d[other])  # fmt: skip
                    else:
                        continue
                    if dist < best:
                        best, best_lab = dist, other
                if best_lab >= 0:
                    new[r, c] = best_lab
                    changed += 1
        labels[:, :] = new
        if changed == 0:
            return
