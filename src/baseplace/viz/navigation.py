"""A planned base path over the regions and the obstacle space, as seed 000 Fig. 4."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path as FilePath

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from baseplace.files import atomic_write
from baseplace.geometry.poses import FloatArray
from baseplace.navigation.navmap import NavigationMap
from baseplace.navigation.planners import Path
from baseplace.viz.regions import region_colours

PATH_COLOURS = {"rrt": "orange", "regions": "deepskyblue"}


def plot_navigation(
    navmap: NavigationMap,
    paths: Sequence[Path],
    start: FloatArray,
    goal: FloatArray,
    out: FilePath,
    title: str = "",
) -> None:
    """Write a PNG: regions in colour, obstacle cells grey, graph edges, the paths, start and goal.

    Args:
        navmap: the navigation map.
        paths: planned paths (one colour per planner).
        start: (3,) start pose x, y, yaw.
        goal: (3,) goal pose x, y, yaw.
        out: PNG path (written atomically).
        title: figure title.
    """
    seg = navmap.seg
    hmap = seg.hmap
    h, w = hmap.shape
    img = np.ones((h, w, 3))
    colours = region_colours(len(seg.regions))
    for r in seg.regions:
        img[seg.labels == r.id] = 0.55 + 0.45 * colours[r.id]  # pale, so that the path stands out
    img[navmap.obstacles] = 0.35
    x0, y0, x1, y1 = navmap.bounds
    fig, ax = plt.subplots(figsize=(7.0, 7.0 * h / max(w, 1) + 0.6), dpi=110)
    ax.imshow(img, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    for _, _, e in navmap.graph.edges(data=True):
        ax.plot([e["p_s"][0], e["p_e"][0]], [e["p_s"][1], e["p_e"][1]],
                color="lime" if e["traversable"] else "red", linewidth=1.2)  # fmt: skip
    for p in paths:
        colour = PATH_COLOURS.get(p.planner, "orange")
        ax.plot(p.poses[:, 0], p.poses[:, 1], color=colour, linewidth=2.2,
                label=f"{p.planner}: {p.length:.2f} m, {p.time_ms:.0f} ms")  # fmt: skip
    for pose, name, colour in ((start, "start", "black"), (goal, "goal", "magenta")):
        x, y, yaw = (float(v) for v in pose)
        ax.add_patch(plt.Circle((x, y), navmap.radius, fill=False, color=colour, linewidth=1.5))
        ax.arrow(x, y, 0.8 * navmap.radius * np.cos(yaw), 0.8 * navmap.radius * np.sin(yaw), color=colour,
                 width=0.015, length_includes_head=True)  # fmt: skip
        ax.annotate(name, (x, y), textcoords="offset points", xytext=(6, 6), fontsize=8, color=colour)
    if paths:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(
        title or "base path (grey: obstacles; red: non-traversable edges; green: traversable)", fontsize=9
    )
    fig.tight_layout()
    with atomic_write(out, "PNG") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
