"""The clearance a placement keeps from the scene: its accepted range, checked without the collision model.

:mod:`baseplace.world.sensor_resolution` derives the default clearance from the cloud's noise;
the range is checked here, math only, so that front ends refuse a wrong ``--clearance`` before the
collision model's imports (coal, numba), and the settings and the environment check it again.
"""

from __future__ import annotations

import math

from baseplace.errors import InputError

MAX_CLEARANCE = 0.1
"""The largest clearance [m] accepted: more would forbid most grasps outright."""


def check_clearance(clearance: float | None) -> None:
    """Raise InputError unless ``clearance`` is None or a finite distance in [0, :data:`MAX_CLEARANCE`] [m]."""
    if clearance is None:
        return
    if not (
        isinstance(clearance, int | float) and math.isfinite(clearance) and 0 <= clearance <= MAX_CLEARANCE
    ):
        raise InputError(f"clearance must be a finite distance in [0, {MAX_CLEARANCE}] m, got {clearance}")
