from __future__ import annotations

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace_experiments.surface_truth import PointMapCalibration, agreement


def test_calibration_recovers_a_known_scale_and_keeps_zero_poses_zero():
    rng = np.random.default_rng(0)
    rs = np.r_[np.zeros(10), rng.uniform(0.05, 0.9, 40)]
    truth = 0.7 * rs + np.r_[np.zeros(10), rng.normal(0, 0.01, 40)]
    cal = PointMapCalibration.fit(rs, truth)
    assert cal.scale == pytest.approx(0.7, abs=0.02) and cal.poses == 40
    assert np.all(cal(rs)[:10] == 0) and np.all(cal(np.array([2.0])) <= 1.0)
    with pytest.raises(InputError, match="no development pose"):
        PointMapCalibration.fit(np.zeros(3), np.ones(3))


def test_agreement_by_hand():
    rs = np.array([0.0, 0.0, 0.5, 0.2])
    truth = np.array([0.0, 0.1, 0.3, 0.3])
    a = agreement(rs, truth)
    assert a["mae"] == pytest.approx((0 + 0.1 + 0.2 + 0.1) / 4)
    assert a["mae_nonzero_rs"] == pytest.approx(0.15) and a["bias_nonzero_rs"] == pytest.approx(0.05)
    assert a["overestimated_nonzero_rs"] == 1 and a["zero_rs_but_ik_reaches"] == 1 and a["nonzero_rs"] == 2
