"""The sort-based unique helpers against numpy's own np.unique (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.arrays import unique_ints, unique_ints_first, unique_inverse


@pytest.mark.parametrize("n", [0, 1, 2, 7, 1000])
@pytest.mark.parametrize("seed", [0, 1])
def test_unique_helpers_match_np_unique(n, seed):
    a = np.random.default_rng(seed).integers(-40, 40, n)
    assert np.array_equal(unique_ints(a), np.unique(a))
    values, first = unique_ints_first(a)
    expected, expected_first = np.unique(a, return_index=True)
    assert np.array_equal(values, expected) and np.array_equal(first, expected_first)
    for arr in (a, np.sort(a)):  # unsorted: np.unique's path; sorted: the linear one
        values, inverse = unique_inverse(arr)
        expected, expected_inverse = np.unique(arr, return_inverse=True)
        assert np.array_equal(values, expected) and np.array_equal(inverse, expected_inverse.ravel())
        assert np.array_equal(values[inverse], arr)
