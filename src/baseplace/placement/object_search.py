"""Seed 004 end to end: verified placements around an object, ranked, and the one the base reaches.

The radial search (Algorithm 1) or the reachability-map candidates, the shared verification
(:func:`~baseplace.placement.irm_candidates.verify_candidates`), the robustness score
(:class:`~baseplace.placement.robustness.RobustnessScorer`), the ranking by motion cost (or by
robustness) and, with the robot's pose, the pickup loop (Algorithm 2: the first candidate the grid
planner reaches).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from baseplace.geometry.poses import BasePose, FloatArray
from baseplace.navigation.gridnav import GridNavigator
from baseplace.navigation.path import Path
from baseplace.placement.candidates import RadialSettings, motion_costs, pickup, radial_search
from baseplace.placement.irm_candidates import irm_candidates, irm_settings_for, verify_candidates
from baseplace.placement.pipeline import ObjectChecks
from baseplace.placement.robustness import RobustnessScorer, RobustnessSettings, rank_by_robustness
from baseplace.placement.verified import Placement
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.world.occupancy import OccupancyGrid


@dataclass
class ObjectSearch:
    """What :func:`search_around_object` found.

    Attributes:
        placements: verified placements, best first.
        motion_costs: seed 004's ``MotionCost`` of each [m], from the robot's pose (or the object's).
        rejected: (x, y) [m] and the reason of each rejected position, in the order tried.
        path: the base path to ``chosen``, or None.
        chosen: the first placement the grid planner reaches from the robot's pose, or None.
        navigated: whether paths were planned (a robot pose was given and a placement found).
        timings_ms: search (candidates and verification), robustness (score and ranking) [ms].
        motion_failures: of the positions rejected for "motion", how many per reason the
            reaching-motion check gave (:data:`~baseplace.placement.motion.MOTION_FAILURES`).
    """

    placements: list[Placement]
    motion_costs: list[float]
    rejected: list[tuple[tuple[float, float], str]]
    path: Path | None = None
    chosen: Placement | None = None
    navigated: bool = False
    timings_ms: dict[str, float] = field(default_factory=dict)
    motion_failures: Counter[str] = field(default_factory=Counter)

    def failures(self) -> dict[str, int]:
        """Rejections per reason, and ``no_path`` when no placement could be driven to."""
        out: dict[str, int] = {}
        for _, why in self.rejected:
            out[why] = out.get(why, 0) + 1
        if self.navigated and self.path is None:
            out["no_path"] = len(self.placements)
        return out


def search_around_object(
    robot: Robot,
    rmap: ReachabilityMap,
    p_o: FloatArray,
    grasps: FloatArray,
    method: Literal["radial", "irm"],
    checks: ObjectChecks,
    grid: OccupancyGrid,
    points: FloatArray | None,
    settings: RadialSettings,
    robustness: RobustnessSettings,
    rng: np.random.Generator,
    robot_pose: FloatArray | None = None,
) -> ObjectSearch:
    """Verified placements for grasping at ``p_o`` (3,) [m] with one of ``grasps`` (K, 4, 4), best first.

    Args:
        robot: the robot.
        rmap: the map of the arm that reaches.
        p_o: the grasp point in the grid's frame [m].
        grasps: world TCP poses; a placement must reach one.
        method: radial (seed 004 Algorithm 1) or irm (reachability map).
        checks: the verification's environment and motion check (:func:`~baseplace.placement.pipeline.object_checks`).
        grid: the occupancy grid.
        points: (N, 3) the scene cloud [m], or None.
        settings: the radial search's settings (``r_r`` is also the planner's radius).
        robustness: the score, the minimum and the ranking.
        rng: randomness of the IK.
        robot_pose: (3,) x, y [m], yaw [rad]: rank by motion cost from it and plan a path; None: from the object.
    """
    t0 = time.perf_counter()
    rejected: list[tuple[tuple[float, float], str]] = []
    motion_failures: Counter[str] = Counter()
    if method == "radial":
        search = radial_search(p_o, settings, points, grid)
        rejected += [(r.xy, str(r.reason)) for r in search.rejected]
        verified, failed = verify_candidates(
            robot, rmap.info.arm, search.candidates, grasps, checks.environment, rng, checks.motion
        )
        rejected += [((c.pose.x, c.pose.y), why) for c, why, _ in failed]
        motion_failures = Counter(reason for _, _, reason in failed if reason is not None)
    else:
        verified = irm_candidates(robot, rmap, p_o, grasps, checks.environment, grid, irm_settings_for(robustness), rng,
                                  checks.motion)  # fmt: skip
    t1 = time.perf_counter()
    if robustness.samples > 0:
        scorer = RobustnessScorer(robot.arm(rmap.info.arm), checks.environment, robustness, checks.motion)
        verified = [scorer.scored(p) for p in verified]
        rejected += [((p.pose.x, p.pose.y), "robustness") for p in verified if scorer.too_low(p)]
        verified = [p for p in verified if not scorer.too_low(p)]
    start = robot_pose if robot_pose is not None else np.r_[p_o[:2], 0.0]
    costs = motion_costs(verified, p_o, BasePose(*start)) if verified else np.zeros(0)
    if robustness.rank == "robustness":  # most robust first, motion cost breaks ties
        ranked = rank_by_robustness(verified, costs.tolist())
    else:
        ranked = [verified[i] for i in np.argsort(costs, kind="stable")]
    ranked_costs = motion_costs(ranked, p_o, BasePose(*start)).tolist() if ranked else []
    t2 = time.perf_counter()
    out = ObjectSearch(ranked, ranked_costs, rejected, motion_failures=motion_failures)
    if robot_pose is not None and ranked:
        # seed 004 Algorithm 2 re-ranks by motion cost after each failure; the robustness order is kept
        result = pickup(ranked, p_o, BasePose(*robot_pose), GridNavigator(grid, settings.r_r),
                        rerank=robustness.rank != "robustness")  # fmt: skip
        out.path, out.chosen, out.navigated = result.path, result.chosen, True
    out.timings_ms = {"search": (t1 - t0) * 1e3, "robustness": (t2 - t1) * 1e3}
    return out


__all__ = ["ObjectSearch", "search_around_object"]
