"""``baseplace view MAP --out map.png``: slices of a reachability map itself (issue 29, item 6).

Oracle: the fraction of reachable orientation bins per voxel counted here from the map's stored
cells and counts, and the PNG's own pixels.
"""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from baseplace.reachability.storage import save_map
from baseplace.viz.map_view import plot_map_slices
from conftest import run_cli


def _fractions_by_hand(rmap) -> np.ndarray:
    """(nx, ny, nz): reachable bins / bins per voxel, from cells, counts and the support test."""
    grid, info = rmap.grid, rmap.info
    index = rmap.counts / rmap.counts.max()
    floor = info.support_count / rmap.counts.max() * info.support_threshold if info.supported else 0.0
    out = np.zeros(grid.shape)
    ijk = np.unravel_index(rmap.cells[(index >= floor) & (index > 0)] // grid.n_orientations, grid.shape)
    np.add.at(out, ijk, 1.0 / grid.n_orientations)
    return out


def test_map_slices_draw_the_map_s_own_fractions(tiago_map, tmp_path):
    png = tmp_path / "map.png"
    drawn = plot_map_slices(tiago_map, png)
    expected = _fractions_by_hand(tiago_map)
    grid = tiago_map.grid
    assert 3 <= len(drawn) <= 6
    for z, image in drawn.items():
        k = int(np.floor((z - grid.origin[2]) / grid.voxel_size))
        assert np.allclose(image, expected[:, :, k].T, atol=1e-6)
    assert max(float(image.max()) for image in drawn.values()) > 0.2
    pixels = imread(png)[:, :, :3]
    coloured = (pixels.max(axis=2) - pixels.min(axis=2)) > 0.15  # viridis, not white, grey or black
    assert coloured.sum() > 5000


def test_view_a_map_through_the_cli(tiago_map, tmp_path):
    map_file, png = tmp_path / "tiago.rmap", tmp_path / "slices.png"
    save_map(tiago_map, map_file)
    proc = run_cli("view", str(map_file), "--out", str(png))
    assert proc.returncode == 0 and png.stat().st_size > 20_000, proc.stderr
    again = tmp_path / "again.png"
    assert run_cli("view", "--map", str(map_file), "--out", str(again)).returncode == 0 and again.exists()
    bad = run_cli("view", str(map_file), "--out", str(tmp_path / "map.txt"))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "suffix" in bad.stderr
    assert not (tmp_path / "map.txt").exists()
