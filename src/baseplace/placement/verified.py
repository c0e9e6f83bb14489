"""The values of placement: a proposed base pose (:class:`Candidate`) and a verified one (:class:`Placement`).

Every placement method (the OSRM strategies of seed 000, the radial and IRM candidates of seed 004)
returns :class:`Placement`; the seed-004 methods add where the base stands relative to the object
(:class:`ObjectApproach`). The robustness score (:class:`Robustness`) is a value of it too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from baseplace.geometry.poses import BasePose, FloatArray, yaw_of
from baseplace.placement.motion import ReachingMotion


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval (low, high) of a binomial proportion; z = 1.96: 95 %."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class Robustness:
    """A placement's success rate under base error.

    Attributes:
        successes: error draws from which every target was reached without collision.
        samples: error draws.
        low: lower end of the Wilson interval of the rate.
        high: upper end.
    """

    successes: int
    samples: int
    low: float
    high: float

    @property
    def rate(self) -> float:
        """The success rate: successes / samples (0 when there are no samples)."""
        return self.successes / self.samples if self.samples else 0.0

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {"rate": round(self.rate, 4), "ci95": [round(self.low, 4), round(self.high, 4)],
                "successes": self.successes, "samples": self.samples}  # fmt: skip


@dataclass(frozen=True)
class ObjectApproach:
    """Where a seed-004 placement stands relative to the object it grasps.

    Attributes:
        method: "radial" (seed 004 Algorithm 1) or "irm" (reachability map).
        distance: horizontal distance from the object [m].
        ray: index of the radial unit vector it lies on; -1 for IRM placements.
        grasp: index of the grasp pose (of the method's list) the joints reach.
    """

    method: Literal["radial", "irm"]
    distance: float
    ray: int = -1
    grasp: int = -1


@dataclass(frozen=True)
class Candidate:
    """A base pose proposed by a strategy, not yet verified.

    Attributes:
        T_world_base: (4, 4) pose.
        region: planar region id it stands on, or -1 (flat floor baselines).
        reachability: the map's value for it (0 when the strategy does not use the map).
    """

    T_world_base: FloatArray
    region: int
    reachability: float


@dataclass(frozen=True)
class Placement:
    """A verified placement, what every placement method returns.

    Attributes:
        T_world_base: (4, 4) base pose.
        region: planar region id, or -1.
        reachability: the map's value at the pose.
        joints: per target, the arm joint values (n,) that reach it.
        joint_names: names of those joints.
        motions: per target, the checked reaching motion (None when the check was off).
        robustness: the score under base-pose error, if computed
            (:mod:`baseplace.placement.robustness`).
        targets: (K, 4, 4) the world TCP targets the joints reach (one grasp pose for the seed-004
            methods), as the verifier checked them; None when not recorded.
        approach: where it stands relative to the object it grasps (the seed-004 methods), else None.
    """

    T_world_base: FloatArray
    region: int
    reachability: float
    joints: list[FloatArray]
    joint_names: tuple[str, ...]
    motions: list[ReachingMotion] | None = None
    robustness: Robustness | None = None
    targets: FloatArray | None = None
    approach: ObjectApproach | None = None

    @property
    def yaw(self) -> float:
        """Heading of the base x axis projected on the xy plane [rad], in (-pi, pi]."""
        return float(yaw_of(self.T_world_base))

    @property
    def grasp(self) -> int:
        """Index of the grasp pose the joints reach (the seed-004 methods' ``approach.grasp``), else -1."""
        return -1 if self.approach is None else self.approach.grasp

    @property
    def xy(self) -> FloatArray:
        """(2,) position [m]."""
        return self.T_world_base[:2, 3].copy()

    @property
    def pose(self) -> BasePose:
        """The pose projected on the floor (x, y, yaw), the type every base pose converts to."""
        return BasePose.from_matrix(self.T_world_base)


__all__ = ["Candidate", "ObjectApproach", "Placement", "Robustness", "wilson_interval"]
