"""Successes per grid cell and method as heat maps, as seed 004's Fig. 4."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from baseplace.files import atomic_write

TITLES = {"baseline": "fixed pose (baseline)", "radial": "radial (seed 004)", "irm": "IRM-verified"}
PAPER_COLUMN = {"baseline": "baseline", "radial": "proposed"}
"""The seed's Table 1 column each method is compared with (IRM is the seed's future work)."""


def plot_table_grid(result: dict[str, Any], path: str | Path) -> None:
    """Three heat maps side by side: successes out of ``trials`` per cell, row 0 (the short edge) at the bottom.

    Each cell shows the count and, where the seed has a matching column, the seed's count in
    brackets; cells not run are grey. Titles carry the overall rate and the seed's.

    Args:
        result: the dict :func:`baseplace_experiments.table_grid.run_table_grid` returned.
        path: output PNG, written atomically.
    """
    trials = int(result["trials"])
    paper = {tuple(r["cell"]): r for r in result["paper"]["table1"]}
    methods = list(result["grids"])
    fig, axes = plt.subplots(1, len(methods), figsize=(3.0 * len(methods) + 1.2, 4.3), dpi=110,
                             squeeze=False, layout="constrained")  # fmt: skip
    image = None
    for ax, method in zip(axes[0], methods, strict=True):
        grid = np.array(
            [[np.nan if v is None else v for v in row] for row in result["grids"][method]], dtype=float
        )
        cmap = plt.get_cmap("RdYlGn").with_extremes(bad="0.85")
        image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, vmin=0, vmax=trials)
        column = PAPER_COLUMN.get(method)
        for j in range(grid.shape[0]):
            for i in range(grid.shape[1]):
                text = "-" if np.isnan(grid[j, i]) else f"{int(grid[j, i])}"
                if column is not None:
                    text += f"\n({paper[(i, j)][column][0]})"
                ax.text(i, j, text, ha="center", va="center", fontsize=10)
        total = result["totals"][method]
        title = f"{TITLES.get(method, method)}\n{total['rate']:.1f}% ({total['success']}/{total['success'] + total['failure']})"
        if column is not None:
            title += f", seed {result['paper']['success_rate'][column]:.1f}%"
        ax.set_title(title, fontsize=9)
        ax.set_xticks(range(grid.shape[1]))
        ax.set_yticks(range(grid.shape[0]))
        ax.set_xlabel("x (across the width)")
    axes[0][0].set_ylabel("y (from the short edge)")
    if image is not None:
        fig.colorbar(image, ax=axes[0].tolist(), shrink=0.7, label=f"successes of {trials}")
    fig.suptitle(f"{result['robot']}: grasp successes per cell (seed 004 Fig. 4; seed's HSR counts in brackets)",
                 fontsize=9)  # fmt: skip
    with atomic_write(path, "PNG") as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)


__all__ = ["plot_table_grid"]
