"""Planes of height-map regions: local normals per cell and least-squares planes per region."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from baseplace.terrain.heightmap import FloatArray, HeightMap


@dataclass(frozen=True)
class LocalPlanes:
    """A plane fitted to the (2k+1)^2 window around every cell.

    Attributes:
        normals: (H, W, 3) unit normals pointing up, NaN where the fit is undefined.
        rms: (H, W) RMS residual of the fit [m], inf where undefined.
    """

    normals: FloatArray
    rms: FloatArray


def local_planes(
    heights: FloatArray, resolution: float, half_window: int = 2, min_fill: float = 0.6
) -> LocalPlanes:
    """Fit ``z = a x + b y + c`` around every cell with box-filter sums (no loop over cells).

    Args:
        heights: (H, W) heights [m], NaN where unknown.
        resolution: cell edge [m].
        half_window: k, the window is (2k + 1) cells wide.
        min_fill: share of known cells a window needs for a fit.
    """
    k = half_window
    offsets = np.arange(-k, k + 1) * resolution
    X, Y = np.meshgrid(offsets, offsets)  # X along columns (x), Y along rows (y)
    known = np.isfinite(heights)
    m = known.astype(float)
    hc = np.where(known, heights, 0.0)
    centre = hc

    from scipy import ndimage  # here: a cached terrain never imports it (0.5 s)

    def corr(img: FloatArray, kernel: FloatArray) -> FloatArray:
        return ndimage.correlate(img, kernel, mode="constant", cval=0.0)

    ones = np.ones_like(X)
    S1, Sx, Sy = corr(m, ones), corr(m, X), corr(m, Y)
    Sxx, Sxy, Syy = corr(m, X * X), corr(m, X * Y), corr(m, Y * Y)
    # Heights relative to the centre cell keep the sums well conditioned.
    Sh = corr(hc, ones) - centre * S1
    Sxh = corr(hc, X) - centre * Sx
    Syh = corr(hc, Y) - centre * Sy
    Shh = corr(hc * hc, ones) - 2 * centre * corr(hc, ones) + centre * centre * S1
    A = np.stack(
        [np.stack([Sxx, Sxy, Sx], -1), np.stack([Sxy, Syy, Sy], -1), np.stack([Sx, Sy, S1], -1)], axis=-2
    )
    rhs = np.stack([Sxh, Syh, Sh], -1)
    ok = known & (S1 >= min_fill * X.size)
    det = np.linalg.det(A)
    ok &= np.abs(det) > 1e-18
    sol = np.zeros_like(rhs)
    sol[ok] = np.linalg.solve(A[ok], rhs[ok][..., None])[..., 0]
    a, b, c = sol[..., 0], sol[..., 1], sol[..., 2]
    rss = Shh - (a * Sxh + b * Syh + c * Sh)
    normals = np.stack([-a, -b, np.ones_like(a)], -1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~ok] = np.nan
    rms = np.full(heights.shape, np.inf)
    rms[ok] = np.sqrt(np.maximum(rss[ok], 0.0) / S1[ok])
    return LocalPlanes(normals, rms)


def fit_region_planes(
    hmap: HeightMap, labels: NDArray[np.int32], n_labels: int, heights: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.int64]]:
    """Least-squares plane of every region's cells (world coordinates).

    Args:
        hmap: the height map.
        labels: (H, W) region per cell, -1 for none.
        n_labels: number of regions (labels 0 .. n_labels - 1).
        heights: (H, W) heights to fit (default: the raw heights).

    Returns:
        normals (n, 3) pointing up, offsets d (n,) of ``n . p + d = 0``, centroids (n, 3) and cell
        counts (n,); regions with fewer than 3 cells get NaN planes.
    """
    z = hmap.raw if heights is None else heights
    X, Y = hmap.cell_centres()
    sel = (labels >= 0) & np.isfinite(z)
    lab, x, y, h = labels[sel], X[sel], Y[sel], z[sel]

    def s(w: FloatArray | None = None) -> FloatArray:
        return np.bincount(lab, weights=w, minlength=n_labels).astype(float)

    n = s()
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my, mz = s(x) / n, s(y) / n, s(h) / n
        dx, dy, dz = x - mx[lab], y - my[lab], h - mz[lab]
        A = np.zeros((n_labels, 3, 3))
        A[:, 0, 0], A[:, 0, 1], A[:, 1, 1] = s(dx * dx), s(dx * dy), s(dy * dy)
        A[:, 1, 0] = A[:, 0, 1]
        A[:, 2, 2] = 1.0
        rhs = np.stack([s(dx * dz), s(dy * dz), np.zeros(n_labels)], -1)
    good = (n >= 3) & (np.abs(np.linalg.det(A)) > 1e-18)
    sol = np.full((n_labels, 3), np.nan)
    if good.any():
        sol[good] = np.linalg.solve(A[good], rhs[good][..., None])[..., 0]
    normals = np.stack([-sol[:, 0], -sol[:, 1], np.ones(n_labels)], -1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    centroids = np.stack([mx, my, mz], -1)
    d = -np.einsum("ij,ij->i", normals, centroids)
    return normals, d, centroids, n.astype(np.int64)
