"""Top-down pictures of inverse reachability (as seed 000, Fig. 2b)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray


def plot_irm_topdown(
    xs: NDArray[np.float64],
    ys: NDArray[np.float64],
    summed: NDArray[np.float64],
    target_xyz: NDArray[np.float64],
    target_dir: NDArray[np.float64],
    best_xy_yaw: tuple[float, float, float] | None,
    title: str,
    path: Path,
) -> None:
    """Heat map of reachability summed over base headings, with the target and the best pose.

    Args:
        xs: (W,) cell centres along x [m].
        ys: (H,) cell centres along y [m].
        summed: (H, W) reachability summed over headings.
        target_xyz: (3,) target position [m].
        target_dir: (3,) target approach axis (drawn projected on xy).
        best_xy_yaw: best base pose (x, y, yaw) or None.
        title: figure title.
        path: output PNG.
    """
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=110)
    res = xs[1] - xs[0] if len(xs) > 1 else 1.0
    extent = (xs[0] - res / 2, xs[-1] + res / 2, ys[0] - res / 2, ys[-1] + res / 2)
    shown = np.ma.masked_where(summed <= 0, summed)
    im = ax.imshow(shown, origin="lower", extent=extent, cmap="viridis", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="reachability summed over base headings")
    ax.plot(*target_xyz[:2], marker="*", color="red", markersize=14, label="target")
    d = target_dir[:2]
    if np.linalg.norm(d) > 1e-6:
        d = 0.25 * d / np.linalg.norm(d)
        ax.arrow(*target_xyz[:2], *d, color="red", width=0.01, length_includes_head=True)
    if best_xy_yaw is not None:
        x, y, yaw = best_xy_yaw
        ax.plot(
            x,
            y,
            marker="o",
            color="white",
            markeredgecolor="black",
            markersize=9,
            label="best base pose",
        )
        ax.arrow(x, y, 0.25 * np.cos(yaw), 0.25 * np.sin(yaw), color="white", width=0.01,
                 length_includes_head=True)  # fmt: skip
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
