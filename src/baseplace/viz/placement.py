"""The OSRM summed over orientations drawn over the scene, with placements (seed 000 Fig. 2b)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon as PatchPolygon

from baseplace.placement.osrm import OSRM
from baseplace.placement.verify import Placement


def plot_placement(
    osrm: OSRM,
    placements: list[Placement],
    outline: np.ndarray,
    path: Path,
    title: str,
    routes: list[np.ndarray] | None = None,
) -> None:
    """Write a PNG: regions in grey, non-planar black, OSRM heat map, targets, footprints and routes.

    ``routes`` are base paths (N, 3) (x, y, yaw) drawn in orange, as seed 000 Fig. 4.
    """
    seg = osrm.seg
    hmap = seg.hmap
    h, w = hmap.shape
    img = np.ones((h, w, 3))
    img[hmap.known & (seg.labels < 0)] = 0.0
    for r in seg.regions:
        img[seg.labels == r.id] = 0.55 + 0.35 * ((r.id * 0.37) % 1.0)
    ox, oy = hmap.origin
    extent = (ox, ox + w * hmap.resolution, oy, oy + h * hmap.resolution)
    fig, ax = plt.subplots(figsize=(7.0, 7.0 * h / max(w, 1) + 0.6), dpi=110)
    ax.imshow(img, origin="lower", extent=extent, interpolation="nearest")
    summed = osrm.summed
    shown = np.ma.masked_where(summed <= 0, summed)
    im = ax.imshow(shown, origin="lower", extent=extent, cmap="viridis", interpolation="nearest", alpha=0.9)
    fig.colorbar(im, ax=ax, shrink=0.7, label="OSRM summed over orientations")
    for T in osrm.targets:
        ax.plot(T[0, 3], T[1, 3], marker="*", color="red", markersize=13)
    for p in placements:
        T = p.T_world_base
        pts = outline @ T[:2, :2].T + T[:2, 3]
        ax.add_patch(PatchPolygon(pts, closed=True, fill=False, edgecolor="white", linewidth=1.8))
        ax.arrow(T[0, 3], T[1, 3], 0.3 * T[0, 0], 0.3 * T[1, 0], color="white", width=0.015,
                 length_includes_head=True)  # fmt: skip
    for route in routes or []:
        ax.plot(route[:, 0], route[:, 1], color="orange", linewidth=2.0)
        ax.plot(route[0, 0], route[0, 1], marker="o", color="orange", markersize=7)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
