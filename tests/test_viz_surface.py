from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose
from baseplace.placement.surface_map import build_surface_map
from baseplace.placement.surface_sampling import SurfaceSample
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.viz.surface import plot_sampling_comparison, plot_surface_map, sample_array, sample_spread

TABLE = "0,0;1.4,0;1.4,0.65;0,0.65"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def small_map(pr2):
    rmap = build_map(pr2, "right", BuildSettings(samples=300_000, seed=1))
    return build_surface_map(pr2, {"right": rmap}, TABLE, 0.74, resolution=0.1, orientations=8)


@pytest.fixture(scope="module")
def poses(small_map):
    cells, _ = small_map.cell_poses()
    return cells[:: max(1, len(cells) // 40)]


def _is_png(path):
    data = path.read_bytes()
    return len(data) > 1000 and data.startswith(PNG_MAGIC)


def test_plot_surface_map_writes_a_png(small_map, poses, tmp_path):
    assert small_map.values.max() > 0
    plain = tmp_path / "plain.png"
    plot_surface_map(small_map, plain)
    assert _is_png(plain)
    samples = [SurfaceSample(BasePose(float(x), float(y), float(t)), 0.5, 0.5) for x, y, t in poses[:10]]
    with_samples = tmp_path / "samples.png"
    plot_surface_map(small_map, with_samples, samples=samples, title="table")
    assert _is_png(with_samples)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.png", "samples.png"]  # no temporaries left


def test_plot_sampling_comparison_writes_a_png(small_map, poses, tmp_path):
    out = tmp_path / "fig3.png"
    plot_sampling_comparison(small_map, poses[:5], poses, out)
    assert _is_png(out)
    empty = tmp_path / "empty.png"
    plot_sampling_comparison(small_map, [], np.zeros((0, 3)), empty)
    assert _is_png(empty)


def test_a_failed_write_leaves_no_file(small_map, poses, tmp_path, monkeypatch):
    with pytest.raises(InputError, match="does not exist"):
        plot_surface_map(small_map, tmp_path / "missing" / "map.png")
    assert not (tmp_path / "missing").exists()

    def broken(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(Figure, "savefig", broken)
    with pytest.raises(OSError, match="disk full"):
        plot_surface_map(small_map, tmp_path / "map.png", samples=poses)
    with pytest.raises(OSError, match="disk full"):
        plot_sampling_comparison(small_map, poses, poses, tmp_path / "fig3.png")
    assert list(tmp_path.iterdir()) == []


def test_sample_spread():
    assert sample_spread([]) == {"count": 0, "cells": 0, "cell_headings": 0, "mean_nn_m": 0.0}
    p = np.array([[0.05, 0.05, 0.0], [0.06, 0.05, 0.1], [0.55, 0.05, np.pi]])
    s = sample_spread(p)
    assert s["count"] == 3 and s["cells"] == 2 and s["cell_headings"] == 2
    assert s["mean_nn_m"] == pytest.approx((0.01 + 0.01 + 0.49) / 3)
    as_samples = [SurfaceSample(BasePose(x, y, t), 1.0, 1.0) for x, y, t in p]
    np.testing.assert_array_equal(sample_array(as_samples), p)
