"""Failure rates per strategy, as seed 000 Fig. 5."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from baseplace.viz.figures import save_figure

REASONS = ("no_ik", "collision", "footprint", "exhausted")


def plot_failure_rates(rows: list[dict[str, Any]], path: Path) -> None:
    """Stacked bars: rejected candidates per query by reason, per scene class and strategy."""
    labels = [f"{r['scene']}\n{r['strategy']}" for r in rows]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * len(rows)), 4.2), dpi=110)
    bottom = np.zeros(len(rows))
    for reason in REASONS:
        per_query = np.array([
            r["failures"].get(reason, 0) / max(1, r["reachable_grasps"]) for r in rows
        ])  # fmt: skip
        ax.bar(range(len(rows)), per_query, bottom=bottom, label=reason)
        bottom += per_query
    ax.set_xticks(range(len(rows)), labels, rotation=90, fontsize=7)
    ax.set_ylabel("rejected candidates per query")
    ax.legend(fontsize=8)
    ax.set_title("Failure reasons per strategy (as seed 000 Fig. 5)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
