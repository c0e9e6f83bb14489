"""Success rates with 95 % intervals that respect the scenes' clustering of grasps (issue 27).

The grasps of one scene share its tray, its neighbours and its planes, so they are not independent
draws: an interval over grasps would be too narrow. :func:`scene_bootstrap` resamples whole scenes
with replacement within each stratum (a seed and class: the scenes drawn alike), pools the grasps of
the resampled scenes, and reads the percentile interval of the pooled rate.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from baseplace.errors import InputError

DRAWS = 10_000
"""Bootstrap resamples per interval."""
SEED = 27
"""The bootstrap's random seed (fixed, so an interval is reproducible from the results file)."""


def pooled_rate(strata: Sequence[Sequence[tuple[int, int]]]) -> float | None:
    """Successes over trials [%] pooled over every scene of every stratum; None without trials."""
    ok = sum(s for stratum in strata for s, _ in stratum)
    n = sum(t for stratum in strata for _, t in stratum)
    return 100.0 * ok / n if n else None


def scene_bootstrap(
    strata: Sequence[Sequence[tuple[int, int]]], draws: int = DRAWS, seed: int = SEED, level: float = 0.95
) -> tuple[float, float] | None:
    """Percentile interval [%] of the pooled success rate, resampling scenes within each stratum.

    Args:
        strata: per stratum (a seed and class), per scene ``(successes, trials)``; a scene may have
            0 trials (no counted grasp): it is drawn like the others and adds nothing.
        draws: resamples.
        seed: the resampling's random seed.
        level: the interval's coverage.

    Returns:
        (low, high) [%], or None when no scene has a trial. A resample whose scenes hold no trial
        has no rate and is left out of the percentiles.
    """
    if draws < 1 or not 0.0 < level < 1.0:
        raise InputError(f"draws must be >= 1 and level in (0, 1), got {draws} and {level}")
    if pooled_rate(strata) is None:
        return None
    rng = np.random.default_rng(seed)
    ok = np.zeros(draws)
    n = np.zeros(draws)
    for stratum in strata:
        if not stratum:
            continue
        a = np.asarray(stratum, dtype=float).reshape(-1, 2)
        pick = rng.integers(len(a), size=(draws, len(a)))
        ok += a[pick, 0].sum(axis=1)
        n += a[pick, 1].sum(axis=1)
    rates = 100.0 * ok[n > 0] / n[n > 0]
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(rates, [tail, 100.0 - tail])
    return float(low), float(high)


__all__ = ["DRAWS", "SEED", "pooled_rate", "scene_bootstrap"]
