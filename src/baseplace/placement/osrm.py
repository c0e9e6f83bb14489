"""The Oriented Surface Reachability Map (seed 000, section III-A, Algorithm 1).

For every planar-region cell within arm reach of the targets and ``l`` orientations gamma, the
OSRM holds the IRM value of the plane-constrained base pose ``p_{x,y,gamma}``, the minimum over all
targets. Poses whose footprint does not fit inside the region are zero: the region mask is eroded
by the footprint rasterized at each orientation (the exact polygon test runs again at
verification).
"""

from __future__ import annotations

import math
import time
from collections.abc import Collection
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from baseplace.geometry.poses import FloatArray
from baseplace.geometry.surface_poses import plane_base_poses, plane_frame
from baseplace.reachability.rmap import ReachabilityMap, ReachabilityQuery, inverse_reachability
from baseplace.terrain.segmentation import PlanarRegion, Segmentation


@dataclass(frozen=True)
class OSRM:
    """Reachability of plane-constrained base poses over a segmentation.

    Attributes:
        seg: the planar regions.
        values: (H, W, l) reachability per cell and orientation; 0 off-region, out of reach or
            where the footprint does not fit.
        gammas: (l,) orientations [rad].
        targets: (K, 4, 4) world targets.
        near: (H, W) region cells within arm reach of every target (whether or not the footprint fits).
        reach: the horizontal reach used [m].
        fits: (H, W) cells within reach where the footprint fits at some orientation.
        build_ms: construction time [ms].
    """

    seg: Segmentation
    values: NDArray[np.float32]
    gammas: FloatArray
    targets: FloatArray
    near: NDArray[np.bool_]
    reach: float
    fits: NDArray[np.bool_]
    build_ms: float

    @property
    def summed(self) -> NDArray[np.float32]:
        """(H, W) reachability summed over orientations (seed 000 Fig. 2b)."""
        return self.values.sum(axis=2)

    def poses(self, rows: NDArray[np.int64], cols: NDArray[np.int64], gammas: FloatArray) -> FloatArray:
        """World base poses (N, 4, 4) at cell centres with orientations ``gammas`` (N,)."""
        X, Y = self.seg.hmap.centres_at(rows, cols)
        labels = self.seg.labels[rows, cols]
        out = np.empty((len(rows), 4, 4))
        for rid in np.unique(labels):
            sel = labels == rid
            r = self.seg.regions[int(rid)]
            out[sel] = plane_base_poses(X[sel], Y[sel], gammas[sel], r.normal, r.d)
        return out

    def gamma_to_target(self, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> FloatArray:
        """The gamma (N,) that points the base's forward (x) axis at the targets' centroid."""
        X, Y = self.seg.hmap.centres_at(rows, cols)
        goal = self.targets[:, :3, 3].mean(axis=0)
        out = np.empty(len(rows))
        labels = self.seg.labels[rows, cols]
        for rid in np.unique(labels):
            sel = labels == rid
            r = self.seg.regions[int(rid)]
            R0 = plane_frame(r.normal)
            p = np.c_[X[sel], Y[sel]]
            z = r.height_at(p)
            d = goal - np.c_[p, z]
            out[sel] = np.arctan2(d @ R0[:, 1], d @ R0[:, 0])  # in-plane direction in the R0 frame
        return out


def footprint_kernels(outline: FloatArray, gammas: FloatArray, resolution: float) -> list[NDArray[np.uint8]]:
    """Erosion kernels of the footprint at every orientation (cached: they depend on nothing else)."""
    key = (
        np.asarray(outline, dtype=float).tobytes(),
        np.asarray(gammas, dtype=float).tobytes(),
        float(resolution),
    )
    if key not in _KERNELS:
        if len(_KERNELS) > 32:
            _KERNELS.clear()
        _KERNELS[key] = [footprint_kernel(outline, float(g), resolution) for g in gammas]
    return _KERNELS[key]


_KERNELS: dict[tuple[bytes, bytes, float], list[NDArray[np.uint8]]] = {}


def footprint_kernel(outline: FloatArray, gamma: float, resolution: float) -> NDArray[np.uint8]:
    """The footprint (K, 2) [m] rotated by gamma, rasterized as an erosion kernel in cells.

    The kernel covers every cell whose centre lies within half a cell's diagonal of the footprint,
    so an eroded mask never admits a pose whose footprint pokes out of the region's cells.
    """
    c, s = math.cos(gamma), math.sin(gamma)
    pts = outline @ np.array([[c, s], [-s, c]])
    half = math.ceil(np.abs(pts).max() / resolution) + 1
    size = 2 * half + 1
    scale = 8  # rasterize at 1/8 cell, then mark cells touched
    img = np.zeros((size * scale, size * scale), dtype=np.uint8)
    poly = ((pts / resolution + half + 0.5) * scale).round().astype(np.int32)
    cv2.fillPoly(img, [poly], 1)
    img = cv2.dilate(img, np.ones((scale // 2 * 2 + 1, scale // 2 * 2 + 1), np.uint8))
    return (img.reshape(size, scale, size, scale).max(axis=(1, 3)) > 0).astype(np.uint8)


def _plane_values(
    query: ReachabilityQuery, targets: FloatArray, xy: FloatArray, gammas: FloatArray, region: PlanarRegion
) -> NDArray[np.float32]:
    """Min over targets of the IRM values of plane-constrained poses; fused when the map allows."""
    if isinstance(query, ReachabilityMap):
        value = np.ones(len(xy), dtype=np.float32)
        for T in targets:
            np.minimum(value, query.inverse_on_plane(T, xy, gammas, region.normal, region.d), out=value)
        return value
    poses = plane_base_poses(xy[:, 0], xy[:, 1], gammas, region.normal, region.d)
    return inverse_reachability(query, targets, poses)


def build_osrm(
    seg: Segmentation,
    query: ReachabilityQuery,
    targets: FloatArray,
    outline: FloatArray,
    reach: float,
    n_orientations: int = 36,
    regions: Collection[int] | None = None,
) -> OSRM:
    """Algorithm 1 of seed 000, vectorized over cells and orientations.

    Args:
        seg: planar regions.
        query: the reachability map (or an arm combination).
        targets: (K, 4, 4) world targets; all must be reachable (min over targets).
        outline: (F, 2) base footprint in the base frame [m].
        reach: largest horizontal distance [m] from the base origin to a reachable TCP.
        n_orientations: l, orientations per cell (seed 000: 36).
        regions: the ids of the regions the base may stand on (default: every region).
    """
    start = time.perf_counter()
    hmap = seg.hmap
    h, w = hmap.shape
    gammas = np.arange(n_orientations, dtype=np.float64) * (2 * math.pi / n_orientations)
    values = np.zeros((h, w, n_orientations), dtype=np.float32)
    X, Y = hmap.cell_centres()
    near = np.ones((h, w), dtype=bool)
    for T in targets:
        near &= np.hypot(X - T[0, 3], Y - T[1, 3]) <= reach
    near &= seg.labels >= 0
    fits_any = np.zeros((h, w), dtype=bool)
    kernels = footprint_kernels(outline, gammas, hmap.resolution)
    distinct: dict[bytes, int] = {}  # a disc footprint has one kernel for all orientations
    kernel_of = [distinct.setdefault(k.tobytes() + bytes(k.shape), i) for i, k in enumerate(kernels)]
    pad = max(k.shape[0] for k in kernels)
    for r in seg.regions:
        if regions is not None and r.id not in regions:
            continue
        cand = (seg.labels == r.id) & near
        if not cand.any():
            continue
        rows, cols = np.nonzero(cand)
        # Erode only the window around the candidate cells (plus the kernel's reach).
        r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, h)
        c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, w)
        mask = (seg.labels[r0:r1, c0:c1] == r.id).astype(np.uint8)
        eroded = {
            i: cv2.erode(mask, kernels[i], borderValue=0)[rows - r0, cols - c0] > 0 for i in set(kernel_of)
        }
        fits = np.stack([eroded[i] for i in kernel_of], axis=1)
        fits_any[rows, cols] = fits.any(axis=1)
        sel_cell, sel_gamma = np.nonzero(fits)
        if len(sel_cell) == 0:
            continue
        xy = np.c_[X[rows[sel_cell], cols[sel_cell]], Y[rows[sel_cell], cols[sel_cell]]]
        values[rows[sel_cell], cols[sel_cell], sel_gamma] = _plane_values(
            query, targets, xy, gammas[sel_gamma], r
        )
    build_ms = (time.perf_counter() - start) * 1e3
    return OSRM(seg, values, gammas, np.asarray(targets, dtype=float), near, reach, fits_any, build_ms)
