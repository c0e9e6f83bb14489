"""The one base-path type.

Every planner returns a :class:`Path`: the scanned scene's planners
(:mod:`baseplace.navigation.planners`) and the occupancy-grid planner (:mod:`baseplace.navigation.gridnav`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from baseplace.geometry.poses import FloatArray


@dataclass(frozen=True)
class Path:
    """A base path.

    Attributes:
        poses: (N, 3) x, y, yaw [m, m, rad], from the start to the goal.
        planner: "rrt" or "regions" (a scanned scene), "grid" (an occupancy grid).
        time_ms: planning time [ms].
        regions: the region ids the path passes, in order.
    """

    poses: FloatArray
    planner: str
    time_ms: float
    regions: tuple[int, ...]

    @property
    def length(self) -> float:
        """Length [m] of the path's xy polyline."""
        return float(np.linalg.norm(np.diff(self.poses[:, :2], axis=0), axis=1).sum())

    def dense(self, step: float = 0.01) -> FloatArray:
        """(M, 2) xy points along the path, at most ``step`` [m] apart."""
        out = [self.poses[:1, :2]]
        for a, b in itertools.pairwise(self.poses[:, :2]):
            n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
            out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
        return np.concatenate(out)


__all__ = ["Path"]
