"""The point index's sphere queries against scipy's k-d tree (an independent oracle)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from baseplace.errors import InputError
from baseplace.world.point_index import PointIndex


def _scene(rng: np.random.Generator, n: int = 20_000) -> np.ndarray:
    """A noisy table top, a floor and a bottle: surfaces, as a depth camera sees them."""
    table = np.c_[rng.uniform(0.5, 1.3, n), rng.uniform(-0.4, 0.4, n), 0.75 + rng.normal(0, 0.003, n)]
    floor = np.c_[rng.uniform(-1, 2, n), rng.uniform(-1.5, 1.5, n), rng.normal(0, 0.003, n)]
    a, z = rng.uniform(0, 2 * np.pi, n // 4), rng.uniform(0.75, 0.95, n // 4)
    bottle = np.c_[0.9 + 0.035 * np.cos(a), 0.1 + 0.035 * np.sin(a), z]
    return np.vstack([table, floor, bottle])


@pytest.mark.parametrize("cell,field", [(0.05, 0.02), (0.013, 0.0), (0.2, 0.07)])
def test_clear_and_distances_match_the_kd_tree(cell, field):
    rng = np.random.default_rng(3)
    P = _scene(rng)
    index = PointIndex(P, cell=cell, field_resolution=field)
    tree = cKDTree(P)
    anywhere = np.c_[
        rng.uniform(-1.5, 2.5, 20_000), rng.uniform(-2, 2, 20_000), rng.uniform(-0.3, 1.5, 20_000)
    ]
    near = P[rng.integers(0, len(P), 20_000)] + rng.normal(0, 0.05, (20_000, 3))  # where the hand goes
    C = np.vstack([anywhere, near])
    R = rng.uniform(0.0, 0.12, len(C))
    nearest, _ = tree.query(C)
    truth = nearest > R + 0.004
    clear = index.clear(C, R, clearance=0.004)
    assert np.array_equal(clear, truth), np.flatnonzero(clear != truth)[:10]
    assert 0.2 < truth.mean() < 0.95  # both answers occur
    d = index.distances(C, up_to=0.1)
    near = nearest <= 0.1
    assert np.allclose(d[near], nearest[near], atol=1e-12) and np.all(np.isinf(d[~near]))
    assert index.any_hit(C, R) == bool((nearest <= R).any())
    assert not index.any_hit(C[truth], R[truth], clearance=0.004)


def test_points_exactly_at_the_radius_and_on_cell_borders():
    P = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.1, 0.1], [0.3, 0.3, 0.3]])
    index = PointIndex(P, cell=0.1, field_resolution=0.05)
    C = np.array([[0.2, 0.0, 0.0], [0.1, 0.1, 0.25], [0.5, 0.3, 0.3], [0.35, 0.3, 0.3]])
    R = np.array([0.1, 0.15, 0.2 - 1e-12, 0.05])
    assert index.clear(C, R).tolist() == [False, False, True, False]


def test_empty_cloud_and_bad_input():
    index = PointIndex(np.zeros((0, 3)))
    assert index.clear(np.zeros((2, 3)), 1.0).tolist() == [True, True]
    assert not index.any_hit(np.zeros((1, 3)), 5.0)
    with pytest.raises(InputError, match="shape"):
        PointIndex(np.zeros((4, 2)))
    with pytest.raises(InputError, match="finite"):
        PointIndex(np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(InputError, match="positive"):
        PointIndex(np.zeros((1, 3)), cell=0.0)


def test_seek_is_searchsorted_from_a_lower_bound():
    """The galloping search a query's cell rows use (``_seek``) answers as numpy's binary search."""
    from baseplace.world.point_index import _seek

    rng = np.random.default_rng(5)
    for n in (0, 1, 2, 7, 100, 5000):
        keys = np.sort(rng.integers(0, 3 * n + 5, n)).astype(np.int64)
        for v in rng.integers(-2, 3 * n + 8, 200):
            truth = int(np.searchsorted(keys, v))
            for u in {0, truth // 3, truth // 2, max(truth - 1, 0), truth}:  # every key before u is below v
                assert _seek(keys, u, int(v)) == truth, (n, v, u)
