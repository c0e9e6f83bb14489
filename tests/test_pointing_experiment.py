"""The pointing experiment (docs/protocols/pointing.md): a few scenes by default, the full runs slow."""

from __future__ import annotations

import pytest

from baseplace_experiments.pointing_experiment import (
    HELD_OUT_V1,
    HELD_OUT_V2,
    SEEDS,
    run_scene,
    summarize,
    wilson,
)


def test_the_wilson_interval_against_known_values():
    lo, hi = wilson(81, 263)  # Newcombe (1998), Table I, example (e): 0.2553 to 0.3662
    assert lo == pytest.approx(0.2553, abs=1e-4) and hi == pytest.approx(0.3662, abs=1e-4)
    assert wilson(0, 10)[0] == pytest.approx(0.0, abs=1e-12) and wilson(10, 10)[1] == pytest.approx(1.0)


def test_dev_and_held_out_seeds_are_disjoint_and_large_enough():
    assert not set(SEEDS.dev) & set(SEEDS.held_out) and len(SEEDS.held_out) >= 200


def test_protocol_v3_holds_out_scenes_that_v1_and_v2_did_not_spend():
    for spent in (HELD_OUT_V1, HELD_OUT_V2):
        assert not set(SEEDS.held_out) & set(spent) and not set(SEEDS.dev) & set(spent)


def test_a_few_dev_scenes_select_the_target_within_2_cm():
    rows = [run_scene(seed) for seed in (1, 2)]
    summary = summarize(rows)
    assert summary["selected"] == 2 and summary["within_2cm"] == 2, rows
    assert all(r["error_m"] < 0.02 for r in rows)
    assert set(summary["rules"]) == {"finger3d", "first", "nearest"}
    assert summary["rules"]["finger3d"]["selected"] == summary["selected"]


@pytest.mark.slow
@pytest.mark.parametrize("split", ["dev", "held-out"])
def test_the_full_run(split):
    rows = [run_scene(seed) for seed in SEEDS.seeds(split)]
    summary = summarize(rows)
    assert summary["scenes"] == len(SEEDS.seeds(split))
    assert summary["selection_wilson95"][0] <= summary["selection_rate"] <= summary["selection_wilson95"][1]
