"""Base placement candidates over the occupancy grid, as seed 004 Fig. 2."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from baseplace.files import atomic_write
from baseplace.geometry.poses import FloatArray
from baseplace.placement.verified import Placement
from baseplace.world.occupancy import OccupancyGrid


def plot_candidates(
    grid: OccupancyGrid,
    p_o: FloatArray,
    verified: list[Placement],
    rejected: list[tuple[tuple[float, float], str]],
    out: Path,
    robot_pose: FloatArray | None = None,
    route: FloatArray | None = None,
    title: str = "",
) -> None:
    """Write a PNG of the candidates over the grid (white free, black occupied, grey unknown).

    Drawn: the object, the verified candidates (green, facing the object; the best one larger),
    the rejected positions (red, by reason), the robot and the path to the best candidate.

    Args:
        grid: the occupancy grid.
        p_o: (2,) or (3,) object position [m].
        verified: verified candidates, best first.
        rejected: (x, y) positions and their reasons.
        out: PNG path (written atomically).
        robot_pose: (3,) x, y, yaw of the robot, or None.
        route: (N, 2) or (N, 3) path to the best candidate (x, y[, yaw]), or None.
        title: figure title.
    """
    shade = np.where(grid.data < 0, 0.6, 1.0 - grid.data.astype(float) / 100.0)
    x0, y0, yaw = grid.origin
    span = max(1.2, 1.3 * max([float(np.hypot(*(c.xy - p_o[:2]))) for c in verified] + [1.0]))
    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=110)
    # the grid's rows and columns in the world (origin yaw rotates the image)
    transform = matplotlib.transforms.Affine2D().rotate(yaw).translate(x0, y0) + ax.transData
    h, w = grid.data.shape
    ax.imshow(shade, origin="lower", cmap="gray", vmin=0, vmax=1, interpolation="nearest",
              extent=(0, w * grid.resolution, 0, h * grid.resolution), transform=transform)  # fmt: skip
    colours = {
        "body": "red",
        "arm": "orange",
        "occupancy": "darkred",
        "no_ik": "magenta",
        "collision": "purple",
    }
    for reason in colours:
        pts = np.array([xy for xy, r in rejected if r == reason]).reshape(-1, 2)
        if len(pts):
            ax.plot(
                pts[:, 0], pts[:, 1], "o", color=colours[reason], markersize=4, label=f"rejected: {reason}"
            )
    for i, c in enumerate(verified):
        size = 0.25 if i == 0 else 0.15
        ax.arrow(c.pose.x, c.pose.y, size * np.cos(c.pose.yaw), size * np.sin(c.pose.yaw), color="green",
                 width=0.02 if i == 0 else 0.01, length_includes_head=True)  # fmt: skip
    if verified:
        ax.plot([c.pose.x for c in verified], [c.pose.y for c in verified], "o", color="green", markersize=4,
                label=f"verified candidates ({len(verified)})")  # fmt: skip
    if route is not None:
        ax.plot(route[:, 0], route[:, 1], color="dodgerblue", linewidth=1.8, label="path to the best")
    if robot_pose is not None:
        ax.plot(robot_pose[0], robot_pose[1], "o", color="dodgerblue", markersize=8, label="robot")
        span = max(span, 1.1 * float(np.hypot(*(np.asarray(robot_pose[:2]) - p_o[:2]))))
    ax.plot(p_o[0], p_o[1], "*", color="gold", markeredgecolor="black", markersize=15, label="object")
    ax.set_xlim(p_o[0] - span, p_o[0] + span)
    ax.set_ylim(p_o[1] - span, p_o[1] + span)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or "base placement candidates (seed 004 Fig. 2)", fontsize=9)
    fig.tight_layout()
    try:
        with atomic_write(out, "PNG") as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
