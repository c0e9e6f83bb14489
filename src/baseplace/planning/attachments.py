"""Semantic attachments for task planning with surface maps (seed 002, section III-C).

A symbolic planner (e.g. a PDDL planner with semantic attachments) needs two things from a
surface map:

* a **condition** attachment: can the robot work on the surface from this pose? It is a
  constant-time lookup of R_S; actions such as ``inspect-surface`` or ``pickup-object`` are
  discarded when it is 0, before anything expensive runs;
* a **grounding** attachment: new robot poses on demand, so the planner adds poses while it
  plans instead of fixing their number and places beforehand. Consecutive poses are spread
  around the surface by the eq. 3 discount.

Example::

    smap = load_surface_map("table.smap")
    poses = grounding(smap, np.random.default_rng(0), robot=Robot("pr2"))
    first, second = next(poses), next(poses)       # spread apart
    assert reachability(smap, (first.pose.x, first.pose.y, first.pose.yaw)) > 0
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from baseplace.placement.surface_map import SurfaceMap
from baseplace.placement.surface_sampling import SurfaceSample, SurfaceSampler
from baseplace.robots.model import Robot

if TYPE_CHECKING:
    from baseplace.world.occupancy import OccupancyGrid


def reachability(surface: SurfaceMap, pose: ArrayLike) -> float:
    """Condition attachment: R_S of base pose (x, y, yaw) for the surface, in [0, 1]."""
    return float(surface.reachability(pose)[0])


def grounding(
    surface: SurfaceMap,
    rng: np.random.Generator,
    robot: Robot | None = None,
    occupancy: OccupancyGrid | None = None,
    candidates: int = 40,
) -> Iterator[SurfaceSample]:
    """Grounding attachment: an endless stream of good, spread-out poses for the surface.

    Every pose has R_S > 0, lies in the operational area given by ``occupancy`` and, with
    ``robot``, passed a full collision check against the surface's furniture.

    Raises:
        NothingFoundError: (on ``next``) no valid pose could be drawn.
    """
    sampler = SurfaceSampler(surface, robot, occupancy, candidates)
    while True:
        yield sampler.sample(rng)
