"""The OSRM summed over orientations drawn over the scene, with placements (seed 000 Fig. 2b)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon as PatchPolygon

from baseplace.placement.osrm import OSRM
from baseplace.placement.verify import Placement
from baseplace.viz.figures import save_figure
from baseplace.world.environment import GRASPED
from baseplace.world.grasped_object import GraspedObject


def _rejection_kind(reason: str, contact: tuple[str, str] | None) -> str:
    if reason != "collision" or contact is None:
        return reason
    return "self" if contact[1].startswith("self") else contact[1]


def plot_placement(
    osrm: OSRM,
    placements: list[Placement],
    outline: np.ndarray,
    path: Path,
    title: str,
    routes: list[np.ndarray] | None = None,
    rejected: list[tuple[tuple[float, float], str, tuple[str, str] | None]] | None = None,
    contacts: Counter[tuple[str, str]] | None = None,
    grasped: GraspedObject | None = None,
) -> None:
    """Write a PNG: regions in grey, non-planar black, OSRM heat map, targets, footprints and routes.

    ``routes`` are base paths (N, 3) (x, y, yaw) drawn in orange, as seed 000 Fig. 4. Rejected
    candidates ((x, y), reason, first contact) are crosses coloured by reason, collisions by what
    was touched; the legend lists the most frequent (link, touched) contacts. The grasped object's
    footprint (the only thing the hand may touch) is outlined in cyan.
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
    colours = {"footprint": "0.35", "no_ik": "tab:orange", "support": "tab:red", "obstacle": "magenta",
               GRASPED: "tab:blue", "self": "yellow", "motion": "tab:green", "collision": "magenta"}  # fmt: skip
    kinds = [(p, _rejection_kind(why, c)) for p, why, c in rejected or []]
    for key in {k for _, k in kinds} - set(colours):  # a reason drawn in no colour of its own (a new one)
        colours[key] = "white"
    for key, colour in colours.items():
        xy = np.array([p for p, kind in kinds if kind == key]).reshape(-1, 2)
        if len(xy):
            ax.scatter(xy[:, 0], xy[:, 1], marker="x", s=14, color=colour, linewidths=0.9,
                       label=f"rejected: {key.replace('_', ' ')} ({len(xy)})")  # fmt: skip
    if grasped is not None:
        if grasped.kind == "points":
            ax.scatter(grasped.points[:, 0], grasped.points[:, 1], s=1, color="cyan", label="grasped object")
        else:
            a = np.linspace(0, 2 * np.pi, 64)
            ring = np.c_[np.cos(a), np.sin(a)] * grasped.size[0] / 2 if grasped.kind == "cylinder" else (
                np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * grasped.size[:2] / 2)  # fmt: skip
            c, s = np.cos(grasped.yaw), np.sin(grasped.yaw)
            pts = ring @ np.array([[c, s], [-s, c]]) + grasped.center[:2]
            ax.add_patch(PatchPolygon(pts, closed=True, fill=False, edgecolor="cyan", linewidth=1.5,
                                      label="grasped object"))  # fmt: skip
    if contacts:
        top = "\n".join(f"{link} - {what}: {n}" for (link, what), n in contacts.most_common(4))
        ax.text(0.01, 0.01, "most frequent contacts (link - touched: candidates)\n" + top, transform=ax.transAxes,
                fontsize=7, va="bottom", ha="left", bbox={"facecolor": "white", "alpha": 0.8})  # fmt: skip
    if ax.get_legend_handles_labels()[0]:  # a legend of nothing warns
        ax.legend(loc="upper right", fontsize=7)
    for route in routes or []:
        ax.plot(route[:, 0], route[:, 1], color="orange", linewidth=2.0)
        ax.plot(route[0, 0], route[0, 1], marker="o", color="orange", markersize=7)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
