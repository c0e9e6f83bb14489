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
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from baseplace.geometry.poses import FloatArray
from baseplace.geometry.surface_poses import plane_base_poses, plane_frame
from baseplace.reachability.rmap import ReachabilityQuery, inverse_reachability
from baseplace.terrain.segmentation import Segmentation


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
        X, Y = self.seg.hmap.cell_centres()
        labels = self.seg.labels[rows, cols]
        out = np.empty((len(rows), 4, 4))
        for rid in np.unique(labels):
            sel = labels == rid
            r = self.seg.regions[int(rid)]
            out[sel] = plane_base_poses(
                X[rows[sel], cols[sel]], Y[rows[sel], cols[sel]], gammas[sel], r.normal, r.d
            )
        return out

    def gamma_to_target(self, rows: NDArray[np.int64], cols: NDArray[np.int64]) -> FloatArray:
        """The gamma (N,) that points the base's forward (x) axis at the targets' centroid."""
        X, Y = self.seg.hmap.cell_centres()
        goal = self.targets[:, :3, 3].mean(axis=0)
        out = np.empty(len(rows))
        labels = self.seg.labels[rows, cols]
        for rid in np.unique(labels):
            sel = labels == rid
            r = self.seg.regions[int(rid)]
            R0 = plane_frame(r.normal)
            p = np.c_[X[rows[sel], cols[sel]], Y[rows[sel], cols[sel]]]
            z = r.height_at(p)
            d = goal - np.c_[p, z]
            out[sel] = np.arctan2(d @ R0[:, 1], d @ R0[:, 0])  # in-plane direction in the R0 frame
        return out


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


def build_osrm(
    seg: Segmentation,
    query: ReachabilityQuery,
    targets: FloatArray,
    outline: FloatArray,
    reach: float,
    n_orientations: int = 36,
) -> OSRM:
    """Algorithm 1 of seed 000, vectorized over cells and orientations.

    Args:
        seg: planar regions.
        query: the reachability map (or an arm combination).
        targets: (K, 4, 4) world targets; all must be reachable (min over targets).
        outline: (F, 2) base footprint in the base frame [m].
        reach: largest horizontal distance [m] from the base origin to a reachable TCP.
        n_orientations: l, orientations per cell (seed 000: 36).
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
    kernels = [footprint_kernel(outline, g, hmap.resolution) for g in gammas]
    for r in seg.regions:
        mask = (seg.labels == r.id).astype(np.uint8)
        cand = mask.astype(bool) & near
        if not cand.any():
            continue
        rows, cols = np.nonzero(cand)
        fits = np.stack([cv2.erode(mask, k, borderValue=0)[rows, cols] > 0 for k in kernels], axis=1)
        fits_any[rows, cols] = fits.any(axis=1)
        sel_cell, sel_gamma = np.nonzero(fits)
        if len(sel_cell) == 0:
            continue
        poses = plane_base_poses(X[rows[sel_cell], cols[sel_cell]], Y[rows[sel_cell], cols[sel_cell]],
                                 gammas[sel_gamma], r.normal, r.d)  # fmt: skip
        values[rows[sel_cell], cols[sel_cell], sel_gamma] = inverse_reachability(query, targets, poses)
    build_ms = (time.perf_counter() - start) * 1e3
    return OSRM(seg, values, gammas, np.asarray(targets, dtype=float), near, reach, fits_any, build_ms)
