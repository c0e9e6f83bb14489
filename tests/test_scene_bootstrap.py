"""The scene bootstrap against independent computations: constant rates and exact enumeration."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace_experiments.scene_bootstrap import pooled_rate, scene_bootstrap


def test_scenes_of_equal_rate_give_a_zero_width_interval():
    strata = [[(2, 4), (1, 2), (3, 6)], [(5, 10), (0, 0)]]  # every scene 50 % (one with no grasp)
    assert pooled_rate(strata) == pytest.approx(50.0)
    assert scene_bootstrap(strata) == pytest.approx((50.0, 50.0))


def _exact_quantile(values: list[float], q: float) -> float:
    """The q quantile of equally weighted ``values``: the smallest v with CDF(v) >= q."""
    ordered = sorted(values)
    return ordered[int(np.ceil(q * len(ordered))) - 1]


def test_a_small_case_matches_exact_enumeration_of_every_resample():
    stratum = [(2, 4), (0, 2), (3, 3)]  # three scenes: 27 equally likely resamples
    rates = []
    for pick in itertools.product(range(3), repeat=3):
        ok = sum(stratum[i][0] for i in pick)
        n = sum(stratum[i][1] for i in pick)
        rates.append(100.0 * ok / n)
    low, high = scene_bootstrap([stratum], draws=20_000)
    assert low == pytest.approx(_exact_quantile(rates, 0.025), abs=1e-9)
    assert high == pytest.approx(_exact_quantile(rates, 0.975), abs=1e-9)
    assert (low, high) == pytest.approx((0.0, 100.0))  # 1/27 each way: both ends reach the extremes


def test_two_strata_are_resampled_separately():
    # stratum A: scenes 0/1 and 1/1; stratum B: one scene 10/10, always drawn. Pooled rate over the 4
    # resamples of A: (10 + a) / 12 with a in {0, 1, 1, 2}: 10/12, 11/12 (twice), 12/12.
    low, high = scene_bootstrap([[(0, 1), (1, 1)], [(10, 10)]], draws=20_000)
    assert low == pytest.approx(100 * 10 / 12) and high == pytest.approx(100.0)
    # were B resampled with A (one stratum), a resample of three 0/1 scenes would reach 0 %
    low_one, _ = scene_bootstrap([[(0, 1), (1, 1), (10, 10)]], draws=20_000)
    assert low_one < low


def test_no_grasp_anywhere_has_no_interval_and_bad_settings_are_refused():
    assert scene_bootstrap([[(0, 0)], []]) is None and pooled_rate([[(0, 0)]]) is None
    with pytest.raises(InputError, match="draws"):
        scene_bootstrap([[(1, 2)]], draws=0)
