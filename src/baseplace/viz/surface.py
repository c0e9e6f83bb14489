"""Top-down pictures of inverse surface reachability maps and of poses sampled from them (seed 002).

* :func:`plot_surface_map`: R_S, maximized over the base headings, around the surface polygon,
  with optional sampled poses as heading arrows.
* :func:`plot_sampling_comparison`: seed 002 Fig. 3, consecutive samples without (a) and with (b)
  the eq. 3 discount side by side.

Files are written atomically: a failed write leaves nothing under the final name.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from baseplace.files import atomic_write
from baseplace.placement.surface_map import SurfaceMap
from baseplace.placement.surface_sampling import SurfaceSample

Samples = Sequence[SurfaceSample] | ArrayLike
"""Base poses: SurfaceSample objects or an (N, 3) array of (x, y, yaw)."""
ARROW = 0.09
"""Length [m] of a sample's heading arrow."""
SPREAD_CELL = 0.1
"""Cell size [m] for counting the distinct cells samples visit."""


def sample_array(samples: Samples) -> NDArray[np.float64]:
    """Samples as an (N, 3) array of (x, y, yaw); N may be 0.

    Args:
        samples: SurfaceSample objects or an (N, 3) array-like of (x, y, yaw).

    Returns:
        (N, 3) float array.
    """
    if isinstance(samples, Sequence) and len(samples) > 0 and isinstance(samples[0], SurfaceSample):
        return np.array(
            [[s.pose.x, s.pose.y, s.pose.yaw] for s in samples if isinstance(s, SurfaceSample)], dtype=float
        )
    arr = np.asarray(samples, dtype=float)
    return arr.reshape(-1, 3) if arr.size else np.zeros((0, 3))


def sample_spread(samples: Samples, cell: float = SPREAD_CELL) -> dict[str, float | int]:
    """How spread out samples are, as drawn in the panel titles of :func:`plot_sampling_comparison`.

    Args:
        samples: SurfaceSample objects or an (N, 3) array of (x, y, yaw).
        cell: cell size [m] for the distinct-cell count.

    Returns:
        ``count``; ``cells``: distinct ``cell``-sized xy cells visited; ``cell_headings``: distinct
        (cell, 45-degree heading sector) pairs visited; ``mean_nn_m``: mean distance [m] in xy from
        each sample to its nearest other sample (0 with fewer than two samples).
    """
    p = sample_array(samples)
    if len(p) == 0:
        return {"count": 0, "cells": 0, "cell_headings": 0, "mean_nn_m": 0.0}
    ij = np.floor(p[:, :2] / cell).astype(np.int64)
    sector = np.floor(np.mod(p[:, 2], 2 * np.pi) / (np.pi / 4)).astype(np.int64) % 8
    mean_nn = 0.0
    if len(p) > 1:
        dist, _ = cKDTree(p[:, :2]).query(p[:, :2], k=2)
        mean_nn = float(dist[:, 1].mean())
    return {
        "count": len(p),
        "cells": len(np.unique(ij, axis=0)),
        "cell_headings": len(np.unique(np.c_[ij, sector], axis=0)),
        "mean_nn_m": mean_nn,
    }


def _draw_map(ax: Axes, smap: SurfaceMap, alpha: float = 1.0) -> AxesImage:
    """R_S max over headings (zeros masked) and the polygon outline, on metre axes."""
    best = smap.values.max(axis=0).T  # (NY, NX): rows are y
    xmin, ymin, xmax, ymax = smap.bounds
    shown = np.ma.masked_where(best <= 0, best)
    im = ax.imshow(shown, origin="lower", extent=(xmin, xmax, ymin, ymax), cmap="viridis",
                   interpolation="nearest", vmin=0.0, vmax=max(float(best.max()), 1e-6), alpha=alpha)  # fmt: skip
    ring = np.vstack([smap.polygon, smap.polygon[:1]])
    ax.plot(ring[:, 0], ring[:, 1], color="black", linewidth=1.6, label="surface")
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    return im


def _draw_samples(ax: Axes, poses: NDArray[np.float64], colour: str, length: float = ARROW) -> None:
    """Each pose as a small arrow from its position along its heading."""
    if len(poses) == 0:
        return
    ax.quiver(poses[:, 0], poses[:, 1], length * np.cos(poses[:, 2]), length * np.sin(poses[:, 2]),
              angles="xy", scale_units="xy", scale=1.0, color=colour, width=0.004, headwidth=3.5,
              headlength=4.0, headaxislength=3.5, zorder=3)  # fmt: skip


def _save(fig: Figure, path: str | Path) -> None:
    """Write the figure as PNG atomically and close it, whatever happens."""
    try:
        with atomic_write(path, "PNG") as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)


def plot_surface_map(
    smap: SurfaceMap, path: str | Path, samples: Samples | None = None, title: str | None = None
) -> None:
    """Heat map of R_S maximized over base headings around the surface, optionally with samples.

    Args:
        smap: the surface map.
        path: output PNG, written atomically.
        samples: base poses drawn as small heading arrows (SurfaceSample objects or (N, 3) x, y, yaw).
        title: figure title; by default the robot, arms, surface height and resolution.

    Raises:
        InputError: the output directory does not exist.
    """
    fig, ax = plt.subplots(figsize=(7.0, 5.6), dpi=110)
    try:
        im = _draw_map(ax, smap)
        fig.colorbar(im, ax=ax, shrink=0.85, label="R_S (max over headings)")
        if samples is not None:
            poses = sample_array(samples)
            _draw_samples(ax, poses, "red", 1.5 * ARROW)
            if len(poses):
                ax.plot([], [], color="red", marker=r"$\rightarrow$", linestyle="none",
                        label=f"{len(poses)} sampled poses")  # fmt: skip
        ax.legend(loc="upper right", fontsize=8)
        default = (
            f"Surface map: {smap.robot} {'+'.join(smap.arms)} ({smap.combine}), surface at {smap.height:.2f} m, "
            f"{smap.resolution:g} m, {len(smap.values)} headings"
        )
        ax.set_title("\n".join(textwrap.wrap(title or default, 75)), fontsize=9)
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    _save(fig, path)


def plot_sampling_comparison(smap: SurfaceMap, without: Samples, with_: Samples, path: str | Path) -> None:
    """Seed 002 Fig. 3: consecutive samples without (a) and with (b) the reachability discount.

    Each panel shows the samples as heading arrows over the faint R_S map and the surface outline;
    its title gives the number of samples, the distinct 0.1 m cells they visit and their mean
    nearest-neighbour distance.

    Args:
        smap: the surface map the samples were drawn from.
        without: samples drawn without the discount.
        with_: samples drawn with the discount.
        path: output PNG, written atomically.

    Raises:
        InputError: the output directory does not exist.
    """
    fig, axes = plt.subplots(1, 2, figsize=(13.0, 5.6), dpi=110, sharey=True)
    try:
        im = None
        for ax, samples, tag, label in ((axes[0], without, "a", "without"), (axes[1], with_, "b", "with")):
            im = _draw_map(ax, smap, alpha=0.35)
            poses = sample_array(samples)
            _draw_samples(ax, poses, "crimson")
            s = sample_spread(poses)
            ax.set_title(
                f"({tag}) {s['count']} samples {label} discount\n"
                f"{s['cells']} distinct {SPREAD_CELL:g} m cells, mean nearest neighbour {s['mean_nn_m']:.3f} m",
                fontsize=9,
            )
        axes[1].set_ylabel("")
        assert im is not None
        fig.suptitle("Consecutive samples from a surface map (as seed 002 Fig. 3)", fontsize=10)
        fig.tight_layout(rect=(0.0, 0.0, 0.92, 1.0))
        fig.colorbar(im, cax=fig.add_axes((0.93, 0.18, 0.012, 0.64)), label="R_S (max over headings)")
    except BaseException:
        plt.close(fig)
        raise
    _save(fig, path)
