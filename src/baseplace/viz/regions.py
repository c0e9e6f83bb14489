"""Planar regions drawn as in seed 000 Fig. 2a: one colour per region, black = non-planar."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import networkx as nx
import numpy as np

from baseplace.terrain.segmentation import Segmentation
from baseplace.viz.figures import save_figure


def region_colours(n: int) -> np.ndarray:
    """N distinct RGB colours in [0, 1], stable for a given n."""
    rng = np.random.default_rng(7)
    base = plt.get_cmap("tab20")(np.arange(20))[:, :3]
    extra = rng.uniform(0.25, 1.0, (max(0, n - 20), 3))
    return np.vstack([base, extra])[:n]


def plot_regions(seg: Segmentation, graph: nx.MultiGraph | None, path: Path, title: str = "") -> None:
    """Write a PNG: regions coloured, non-planar cells black, unknown cells white, graph edges."""
    hmap = seg.hmap
    h, w = hmap.shape
    img = np.ones((h, w, 3))
    img[hmap.known & (seg.labels < 0)] = 0.0
    colours = region_colours(len(seg.regions))
    for r in seg.regions:
        img[seg.labels == r.id] = colours[r.id]
    ox, oy = hmap.origin
    extent = (ox, ox + w * hmap.resolution, oy, oy + h * hmap.resolution)
    size = 7.0
    fig, ax = plt.subplots(figsize=(size, size * h / max(w, 1) + 0.6), dpi=110)
    ax.imshow(img, origin="lower", extent=extent, interpolation="nearest")
    if graph is not None:
        for _, _, e in graph.edges(data=True):
            colour = "lime" if e["traversable"] else "red"
            ax.plot([e["p_s"][0], e["p_e"][0]], [e["p_s"][1], e["p_e"][1]], color=colour, linewidth=1.5)
    for r in seg.regions:
        cx, cy = r.centroid[:2]
        ax.text(cx, cy, f"{r.id}\n{np.degrees(r.tilt):.1f}°", ha="center", va="center", fontsize=7,
                color="black", bbox={"facecolor": "white", "alpha": 0.6, "pad": 1, "edgecolor": "none"})  # fmt: skip
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"{len(seg.regions)} planar regions (black: non-planar; green/red: traversable/not)",
                 fontsize=9)  # fmt: skip
    fig.tight_layout()
    save_figure(fig, path)
