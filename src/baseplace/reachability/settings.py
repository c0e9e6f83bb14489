"""How to build a reachability map: :class:`BuildSettings`, apart from the sampling kernels.

A query that only loads a cached map needs the settings (they key the cache) and none of the build.
"""

from __future__ import annotations

from dataclasses import dataclass

from baseplace.errors import InputError

MAX_SAMPLES = 10**11
DEFAULT_SAMPLES = 200_000_000
"""Joint samples of a default map: 4x seed 000's 5e7, enough samples per cell for the support test
to reach 96 % precision at 99 % recall on TIAGo (docs/maps.md)."""


@dataclass(frozen=True)
class BuildSettings:
    """How to build a map.

    Attributes:
        samples: number of random joint configurations (seed 000 uses 5e7).
        seed: random seed; the same seed gives the same map.
        voxel_size: position resolution [m] (seed 000: 0.05).
        orientation_resolution: largest orientation bin width [rad] (seed 000: 0.8).
        self_collision: drop self-colliding samples (conservative sphere model, ``robots/spheres.py``).
        manipulability: keep the best Yoshikawa manipulability sqrt(det(J J^T)) per cell.
        certify: certify cells with fewer samples than this by IK and record the measured
            precision and recall (``certify.py``); 0 (default): no certification.
        support_threshold: the support a pose needs for the map to call it reachable (the support
            test, :mod:`baseplace.reachability.rmap`); 0: off, every pose in a reached cell is.
            The support count follows from the map's samples per cell
            (:data:`SAMPLES_PER_SUPPORT_COUNT`). A map with the test on records its measured
            precision and recall.
    """

    samples: int = DEFAULT_SAMPLES
    seed: int = 0
    voxel_size: float = 0.05
    orientation_resolution: float = 0.8
    self_collision: bool = False
    manipulability: bool = False
    certify: int = 0
    support_threshold: float = 0.8

    def __post_init__(self) -> None:
        if not (1 <= self.samples <= MAX_SAMPLES):
            raise InputError(f"samples must be between 1 and {MAX_SAMPLES:.0e}, got {self.samples}")
        if self.seed < 0:
            raise InputError(f"seed must be a non-negative integer, got {self.seed}")
        if not (0 <= self.certify <= 2**31):
            raise InputError(f"certify must be a sample count >= 0 (0: off), got {self.certify}")
        if not (0.0 <= self.support_threshold <= 1.0):
            raise InputError(f"support threshold must be in [0, 1] (0: off), got {self.support_threshold}")
