"""Pairs, components and diameters of baseplace.world.neighbours against brute force and scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from baseplace.world.neighbours import component_labels, convex_hull, pairs_within, wider_than


def brute_pairs(points: np.ndarray, radius: float) -> set[tuple[int, int]]:
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    i, j = np.nonzero(np.triu(d <= radius, k=1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_pairs_within_equal_brute_force(dim: int) -> None:
    rng = np.random.default_rng(dim)
    for shift in (0.0, -123.4567, 1e3):
        points = rng.uniform(0.0, 0.3, (600, dim)) + shift
        points[:20] = points[20:40]  # duplicates: distance 0
        found = pairs_within(points, 0.02)
        assert np.all(found[:, 0] < found[:, 1])
        assert len({tuple(r) for r in found.tolist()}) == len(found)  # each pair once
        assert {tuple(r) for r in found.tolist()} == brute_pairs(points, 0.02)


def test_pairs_within_small_inputs() -> None:
    assert pairs_within(np.zeros((0, 3)), 0.1).shape == (0, 2)
    assert pairs_within(np.zeros((1, 3)), 0.1).shape == (0, 2)
    assert pairs_within(np.array([[0.0, 0, 0], [0.3, 0, 0]]), 0.1).shape == (0, 2)


def test_component_labels_match_scipy() -> None:
    rng = np.random.default_rng(5)
    for n, m in ((1, 0), (50, 30), (2000, 1500), (2000, 6000)):
        pairs = rng.integers(0, n, (m, 2)) if m else np.zeros((0, 2), dtype=np.int64)
        labels = component_labels(n, pairs)
        graph = coo_matrix((np.ones(m), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        count, oracle = connected_components(graph, directed=False)
        # the same partition: a one-to-one map between the two labellings
        assert len(set(zip(labels.tolist(), oracle.tolist(), strict=True))) == count
        assert len(np.unique(labels)) == count


def test_chain_component_is_one() -> None:
    n = 5000  # a long path in shuffled order: many hook rounds
    perm = np.random.default_rng(2).permutation(n)
    labels = component_labels(n, np.c_[perm[:-1], perm[1:]])
    assert np.all(labels == labels[0])


def test_wider_than_and_hull_against_brute_force() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        xy = rng.normal(0.0, rng.uniform(0.01, 0.2), (int(rng.integers(1, 300)), 2))
        diameter = np.linalg.norm(xy[:, None] - xy[None], axis=-1).max()
        for size in (0.9 * diameter, 1.1 * diameter, rng.uniform(0.0, 0.5)):
            assert wider_than(xy, float(size)) == bool(diameter > size)
        hull = convex_hull(xy)
        assert np.isclose(np.linalg.norm(xy[hull][:, None] - xy[hull][None], axis=-1).max(), diameter)
    line = np.c_[np.linspace(0, 1, 50), np.linspace(0, 2, 50)]  # collinear: the two ends
    assert sorted(convex_hull(line).tolist()) == [0, 49]
    assert wider_than(line, 2.2) and not wider_than(line, 2.3)
