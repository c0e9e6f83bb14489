"""Figures written to files: atomically, in the format their suffix names."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from baseplace.files import atomic_write


def save_figure(fig: Figure, path: str | Path, **savefig: Any) -> None:
    """Write ``fig`` to ``path`` (``.png``, ``.pdf`` or ``.svg``) atomically, then close it.

    The previous file stays until the new one is complete; a full disk is an
    :class:`~baseplace.files.OutputError` that leaves it untouched.
    """
    path = Path(path)
    try:
        with atomic_write(path, path.suffix.lstrip(".").upper() or "figure") as tmp:
            fig.savefig(tmp, format=path.suffix.lstrip(".").lower() or "png", **savefig)
    finally:
        plt.close(fig)
