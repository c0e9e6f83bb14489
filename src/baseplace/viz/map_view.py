"""Pictures of a reachability map itself: how much of each voxel's orientations the arm reaches.

The value drawn per position voxel is the fraction of its orientation bins whose cell the map
calls reachable at the cell's centre (a reached cell whose index passes the support test,
:attr:`~baseplace.reachability.rmap.ReachabilityMap.cell_floor`), in the arm's base frame. The
static figure shows horizontal slices at a few heights; ``view`` also serves the voxels as a
coloured point cloud in the browser (viser).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from baseplace.reachability.rmap import ReachabilityMap


@dataclass(frozen=True)
class VoxelFractions:
    """Per position voxel, the fraction of orientation bins reachable.

    Attributes:
        values: (nx, ny, nz) fractions in [0, 1], indexed as the map's grid.
        origin: (3,) lower corner of the voxel box in the base frame [m].
        voxel_size: voxel edge [m].
    """

    values: NDArray[np.float64]
    origin: tuple[float, float, float]
    voxel_size: float

    def z_centres(self) -> NDArray[np.float64]:
        """(nz,) heights of the voxel layers' centres [m]."""
        return np.asarray(
            self.origin[2] + (np.arange(self.values.shape[2]) + 0.5) * self.voxel_size, dtype=float
        )

    def slice_heights(self, count: int = 6) -> NDArray[np.int64]:
        """Up to ``count`` layer indices, evenly spread over the layers that hold a reachable voxel."""
        layers = np.flatnonzero(self.values.max(axis=(0, 1)) > 0)
        if len(layers) == 0:
            return layers
        return np.unique(
            np.round(np.linspace(layers[0], layers[-1], min(count, len(layers)))).astype(np.int64)
        )


def voxel_fractions(rmap: ReachabilityMap) -> VoxelFractions:
    """The fraction of reachable orientation bins of every voxel of ``rmap``'s grid."""
    grid = rmap.grid
    reachable = rmap.cells[rmap.index >= rmap.cell_floor]
    per_voxel = np.bincount(reachable // grid.n_orientations, minlength=grid.n_voxels)
    values = (per_voxel / grid.n_orientations).reshape(grid.shape)
    return VoxelFractions(values, tuple(float(v) for v in grid.origin), float(grid.voxel_size))  # type: ignore[arg-type]


def plot_map_slices(
    rmap: ReachabilityMap, out: str | Path, count: int = 6
) -> dict[float, NDArray[np.float64]]:
    """Write a PNG of horizontal slices of :func:`voxel_fractions` (x right, y up, base frame).

    Voxels no orientation reaches stay blank. Returns what each slice draws: its height [m] ->
    the (ny, nx) image of fractions (rows y, columns x).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from baseplace.files import atomic_write

    fractions = voxel_fractions(rmap)
    layers = fractions.slice_heights(count)
    cols = max(1, min(3, len(layers)))
    rows = max(1, -(-len(layers) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.8 * rows), squeeze=False)
    nx, ny, _ = fractions.values.shape
    x0, y0, _ = fractions.origin
    extent = (x0, x0 + nx * fractions.voxel_size, y0, y0 + ny * fractions.voxel_size)
    image = None
    drawn: dict[float, NDArray[np.float64]] = {}
    for ax, k in zip(axes.ravel(), layers, strict=False):
        layer = fractions.values[:, :, k].T
        drawn[float(fractions.z_centres()[k])] = layer
        image = ax.imshow(np.ma.masked_equal(layer, 0.0), origin="lower", extent=extent, cmap="viridis", vmin=0.0,
                          vmax=1.0, interpolation="nearest")  # fmt: skip
        ax.set_title(f"z = {fractions.z_centres()[k]:.2f} m", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    for ax in axes.ravel()[len(layers) :]:
        ax.axis("off")
    if image is not None:
        fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.8, label="reachable orientations (fraction)")
    info = rmap.info
    fig.suptitle(f"{info.robot} {info.arm}: reachability map, {info.samples:.3g} samples, "
                 f"{fractions.voxel_size * 100:.0f} cm voxels (base frame)", fontsize=10)  # fmt: skip
    with atomic_write(Path(out), "PNG") as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
    return drawn


def serve_map(rmap: ReachabilityMap, host: str = "127.0.0.1", port: int = 8080, block: bool = True) -> object:
    """Serve the reachable voxels as a point cloud coloured by their fraction (viser), until Ctrl-C."""
    import time

    import matplotlib
    import viser

    fractions = voxel_fractions(rmap)
    ijk = np.argwhere(fractions.values > 0)
    centres = np.asarray(fractions.origin) + (ijk + 0.5) * fractions.voxel_size
    value = fractions.values[tuple(ijk.T)]
    colours = (np.asarray(matplotlib.colormaps["viridis"](value))[:, :3] * 255).astype(np.uint8)
    server = viser.ViserServer(host=host, port=port)
    server.scene.add_frame("/base", axes_length=0.2, axes_radius=0.01)
    server.scene.add_point_cloud("/map", points=centres.astype(np.float32), colors=colours,
                                 point_size=0.6 * fractions.voxel_size)  # fmt: skip
    if block:
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            server.stop()
    return server
