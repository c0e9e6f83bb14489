"""Issue 20 item 3: seed 004's table grid executed with a drawn navigation error and the reaching motion.

Each trial is the table-grid scene of :mod:`baseplace_experiments.table_grid` (trial ``k = 0`` of the cell,
drawn from ``default_rng([seed, i, j, 0])`` in the same order as that experiment: the true bottle,
its estimate, the noisy cloud). Four ways to choose the base pose, all from what the robot sees
(the estimate, the noisy cloud, the occupancy grid):

* ``baseline``: seed 004's predefined pose at the table's short edge;
* ``radial``: seed 004's Algorithms 1 and 2 (radial candidates, pickup by motion cost);
* ``default``: baseplace's default, the IRM-verified candidates with the reaching-motion check on
  (as ``baseplace candidates``, ``IrmSettings()``: with the reach margin against
  the default base error, :func:`~baseplace.placement.irm_candidates.reach_margin`, after protocol v6), fed to the
  same pickup loop;
* ``robust``: the same verified candidates ranked by robustness to base error
  (:class:`~baseplace.placement.robustness.RobustnessSettings` as chosen in
  ``bench/bench_robustness.py``'s development run), the most robust one the grid planner reaches.

Execution: the robot drives to the chosen pose and stops off it by a draw of the default error
model (sigma 3 cm, 2 deg), ``draws`` times per method and trial (the same draws for every method
of a trial). From there it re-plans on its own (:meth:`~baseplace_experiments.execution.ExecutionOracle.execute`):
it tries the grasps of the bottle nearest its base first (the same rule for every method; the
method's own grasp gets no precedence), solves IK itself on its own model from its own starts,
keeping a solution its own voxels of the noisy cloud call free, and plans the reaching motion on
those voxels (transit: nothing touched; approach: only the hand on the bottle). The oracle checks
the executed path state by state on the true table and bottle, and that it ends on the grasp. A draw
succeeds when that holds. The grasps are those of the true bottle (the robot is taken to see the
bottle where it stands, at arm's length); the estimate only chose the placement.

Protocol: docs/protocols/execution_table_grid.md (v4 of ``bench/bench_execution.py``); v1-v3 handed
the robot's planner the oracle's IK solution, found free on the true scene, and tried the default
and robust methods' own grasp first.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from baseplace.geometry.poses import BasePose, FloatArray
from baseplace.navigation.gridnav import GridNavigator
from baseplace.placement.candidates import pickup, radial_search
from baseplace.placement.irm_candidates import IrmSettings, irm_candidates
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.placement.pipeline import object_checks
from baseplace.placement.robustness import BaseErrorModel, RobustnessScorer, RobustnessSettings, perturbed
from baseplace.placement.verified import Placement
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from baseplace.world.grasped_object import find_grasped_object
from baseplace.world.support_plane import (
    SupportSlab,
    cylinder_distance,
    densest_height,
    fit_support_slab,
    with_support_slab,
)
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.table_grid import (
    RobotShapes,
    TableGridSettings,
    object_cloud,
    radial_settings,
    table_cloud,
    table_occupancy,
    true_bottle,
    true_table,
)

EXECUTION_METHODS = ("baseline", "radial", "default", "robust")
SUPPORT_MODELS = ("voxels", "slab", "product")
"""The robot's models of the table top around the bottle, by protocol: v1-v2, v3-v4, v5."""


def trial_scene(
    seed: int, cell: tuple[int, int], s: TableGridSettings
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One trial's (true bottle centre, its estimate, the noisy cloud the robot sees) [m]."""
    rng = np.random.default_rng([seed, *cell, 0])
    p_true = s.cell_centre(*cell)
    p_true[:2] += rng.uniform(-s.placement_noise, s.placement_noise, 2)
    p_est = p_true + rng.normal(0.0, s.estimate_sigma, 3)
    clean = np.concatenate([table_cloud(s), object_cloud(p_true, s)])
    return p_true, p_est, clean + rng.normal(0.0, s.cloud_sigma, clean.shape)


def execution_trial(robot: Robot, rmap: ReachabilityMap, shapes: RobotShapes, seed: int, cell: tuple[int, int],
                    robust: RobustnessSettings, rank_key: str = "rate", draws: int = 5,
                    s: TableGridSettings | None = None,
                    execution: ExecutionSettings | None = None,
                    cut: str = "support", motion: MotionSettings | None = None,
                    support: str = "voxels") -> dict[str, Any]:  # fmt: skip
    """One table-grid trial executed under navigation error (module docstring); JSON-ready.

    ``robust`` scores the first ``robust.pool`` verified candidates; ``rank_key`` ("rate" or "low",
    the Wilson lower bound) orders them. ``cut``: where the robot's model of the bottle begins,
    "support" (the measured table top, :func:`support_height`) or "estimate" (the estimate's
    bottom; protocol v1). ``motion``: the robot's planner settings, for the default method's
    check and for the execution (default: ``MotionSettings()``). ``support``: the robot's model of
    the table top around the bottle, "voxels" (protocols v1, v2) or "slab" (v3: the points of the
    plane the bottle stands on, fitted within :data:`~baseplace.world.support_plane.RADIUS` of the
    estimate's footprint, their voxels cut down to a thin slab where the fit is good, in every collision model
    of the robot: verification, motion check, robustness score, execution planner), or "product"
    (v5: the models ``baseplace candidates`` builds, :func:`robot_models`).
    """
    if cut not in ("support", "estimate"):
        raise ValueError(f"cut must be 'support' or 'estimate', got {cut!r}")
    if support not in SUPPORT_MODELS:
        raise ValueError(f"support must be one of {', '.join(SUPPORT_MODELS)}, got {support!r}")
    s = s or TableGridSettings()
    p_true, p_est, seen = trial_scene(seed, cell, s)
    occupancy = table_occupancy(s)
    radial = radial_settings(robot, rmap, s)
    start = BasePose(*s.start)
    navigate = GridNavigator(occupancy, radial.r_r, allow_unknown=not radial.unknown_is_risk)
    arm = robot.arm(rmap.info.arm)
    # the robot's own collision model, from the noisy cloud around its estimate
    verify_env, planner, slab = robot_models(robot, rmap.info.arm, seen, p_est, s, cut, support, motion)
    method_grasps = s.grasps(p_est, s.method_top_below)
    true_grasps = s.grasps(p_true)
    chosen: dict[str, tuple[BasePose | None, int, float]] = {}
    t0 = time.perf_counter()
    chosen["baseline"] = (s.baseline_pose(robot) if navigate(start, s.baseline_pose(robot)) is not None else None,
                          -1, time.perf_counter() - t0)  # fmt: skip
    t0 = time.perf_counter()
    found = pickup(radial_search(p_est, radial, seen, occupancy).candidates, p_est, start, navigate).chosen
    chosen["radial"] = (None if found is None else found.pose, -1, time.perf_counter() - t0)
    t0 = time.perf_counter()
    pool = irm_candidates(robot, rmap, p_est, method_grasps, verify_env, occupancy, IrmSettings(),
                          np.random.default_rng([seed, *cell, 1]), planner)  # fmt: skip
    t_pool = time.perf_counter() - t0
    placed = pickup(pool, p_est, start, navigate).chosen
    chosen["default"] = (
        None if placed is None else placed.pose,
        -1 if placed is None else placed.grasp,
        t_pool,
    )
    t0 = time.perf_counter()
    ranked: list[Placement] = []
    if pool:
        scorer = RobustnessScorer(arm, verify_env, robust)
        scored = [scorer.scored(c) for c in pool[: robust.pool]]

        def key(c: Placement) -> tuple[float, float, float]:
            r = c.robustness
            assert r is not None
            return (-(r.low if rank_key == "low" else r.rate), -r.low, -c.reachability)

        ranked = sorted(scored, key=key)
    pick = next((c for c in ranked if navigate(start, c.pose) is not None), None)
    chosen["robust"] = (None if pick is None else pick.pose, -1 if pick is None else pick.grasp,
                        t_pool + time.perf_counter() - t0)  # fmt: skip
    oracle = ExecutionOracle(shapes, true_table(s), true_bottle(p_true, s), execution)
    offsets = BaseErrorModel().sample(np.random.default_rng([30_000 + seed, *cell]), draws)
    out: dict[str, Any] = {"seed": seed, "cell": list(cell), "true": np.round(p_true, 4).tolist(),
                           "pool": len(pool), "methods": {}}  # fmt: skip
    if support == "slab":
        out["slab"] = None if slab is None else slab.to_json()
    for method in EXECUTION_METHODS:
        pose, grasp, t_plan = chosen[method]
        entry: dict[str, Any] = {"plan_s": round(t_plan, 3), "grasp": grasp}
        if pose is None:
            entry.update(pose=None, outcomes=["no_placement"] * draws, success=0)
        else:
            exec_rng = np.random.default_rng(
                [40_000 + seed, *cell]
            )  # the robot's: its IK starts, its planner's seeds
            outcomes = [
                oracle.execute(T, true_grasps, planner, exec_rng) for T in perturbed(pose.matrix(), offsets)
            ]
            entry.update(pose=[round(pose.x, 3), round(pose.y, 3), round(pose.yaw, 3)], outcomes=outcomes,
                         success=sum(o == "ok" for o in outcomes))  # fmt: skip
        out["methods"][method] = entry
    return out


def robot_models(robot: Robot, arm_name: str, seen: np.ndarray, p_est: np.ndarray, s: TableGridSettings,
                 cut: str = "support", support: str = "voxels",
                 motion: MotionSettings | None = None) -> tuple[Environment, MotionChecker, SupportSlab | None]:  # fmt: skip
    """The robot's collision models of a trial's noisy cloud (P, 3): (verification, planner, slab).

    ``support`` "product": the models the product builds for ``baseplace candidates --cloud ...
    --object-shape auto`` (:func:`~baseplace.placement.pipeline.object_checks`): the bottle found in
    the cloud at the estimate ``p_est`` (:func:`~baseplace.world.grasped_object.find_grasped_object`),
    the scene near it at sensor resolution, the plane it stands on exact, the clearance derived from
    the plane's noise; ``cut`` is not used. Otherwise the bottle (around ``p_est``) is cut out above
    ``cut`` ("support": the measured support height; "estimate": the estimate's bottom) and only the
    hand may touch it in the approach; ``support`` "slab" cuts the table's voxels around it down to
    the fitted plane (:mod:`baseplace.world.support_plane`), "voxels" leaves them.
    """
    if support == "product":
        checks = object_checks(robot, arm_name, None, seen, find_grasped_object(seen, p_est),
                               motion or MotionSettings())  # fmt: skip
        assert checks.motion is not None
        return checks.environment, checks.motion, None
    arm = robot.arm(arm_name)
    mine = np.ones(len(seen), dtype=bool)
    bottom = support_height(seen, p_est, s) if cut == "support" else None
    mine[_kept_rows(seen, p_est, s, bottom)] = False  # the bottle as seen: only the hand may touch it
    obstacles = VoxelMap.from_points(seen[~mine], s.voxel_size)
    held = seen[mine]
    slab = None
    if support == "slab":
        z0 = bottom if bottom is not None else float(p_est[2] - s.object_height / 2)
        slab = fit_support_slab(seen, cylinder_distance(p_est, s.object_width / 2), z0, s.voxel_size)

    def model(voxels: VoxelMap) -> dict[str, VoxelMap]:
        return with_support_slab({"obstacle": voxels}, seen, slab)

    verify_env = Environment(robot, model(obstacles))
    planner = MotionChecker(
        robot,
        arm,
        Environment(robot, model(VoxelMap.from_points(seen, s.voxel_size))),
        Environment(
            robot, model(obstacles), grasped=VoxelMap.from_points(held, s.voxel_size), hand_arm=arm.name
        ),
        settings=motion,
    )
    return verify_env, planner, slab


def _kept_rows(
    points: np.ndarray, p_o: np.ndarray, s: TableGridSettings, bottom: float | None = None
) -> np.ndarray:
    """Row indices of ``points`` that :func:`~baseplace_experiments.table_grid.without_object` keeps.

    ``bottom``: the height [m] the object stands on; default: the estimate's bottom, ``p_o``'s z
    less half the object's height (as ``without_object``).
    """
    p = np.asarray(p_o, dtype=float)
    z0 = p[2] - s.object_height / 2 if bottom is None else bottom
    near = np.hypot(points[:, 0] - p[0], points[:, 1] - p[1]) <= s.object_width / 2 + s.hand_clearance
    return np.flatnonzero(~(near & (points[:, 2] > z0 + 0.005)))


def support_height(points: np.ndarray, p_o: np.ndarray, s: TableGridSettings, ring: float = 0.1) -> float:
    """Height [m] of the surface the object at ``p_o`` (3,) stands on, measured in the cloud (P, 3).

    Among the points below ``p_o`` in the ring ``ring`` wide just outside the region
    :func:`_kept_rows` clears: the densest 5 mm height bin (the table top; the slab's rim and the
    legs spread over many heights), then the median of the points within 1 cm of it. The
    estimate's bottom when the ring holds no point. A robot segments the object above its support
    plane; cutting at the estimate's bottom instead leaves the object's lowest centimetres as
    obstacle voxels whenever the estimate is high (protocol v2 of ``bench/bench_execution.py``).
    """
    p = np.asarray(p_o, dtype=float)
    r0 = s.object_width / 2 + s.hand_clearance
    d = np.hypot(points[:, 0] - p[0], points[:, 1] - p[1])
    z = points[(d > r0) & (d <= r0 + ring) & (points[:, 2] < p[2]), 2]
    if len(z) == 0:
        return float(p[2] - s.object_height / 2)
    return float(np.median(z[np.abs(z - densest_height(z, 0.005)) <= 0.01]))


def summarise_execution(
    trials: list[dict[str, Any]], methods: tuple[str, ...] = EXECUTION_METHODS
) -> dict[str, Any]:
    """Per method: successful draws / all draws, outcome counts, mean planning time."""
    out: dict[str, Any] = {}
    for m in methods:
        outcomes = [o for t in trials for o in t["methods"][m]["outcomes"]]
        counts: dict[str, int] = {}
        for o in outcomes:
            counts[o] = counts.get(o, 0) + 1
        ok = counts.get("ok", 0)
        out[m] = {"success": ok, "draws": len(outcomes), "rate": round(ok / len(outcomes), 4) if outcomes else None,
                  "outcomes": counts,
                  "mean_plan_s": round(float(np.mean([t["methods"][m]["plan_s"] for t in trials])), 3)}  # fmt: skip
    return out


__all__ = ["EXECUTION_METHODS", "execution_trial", "robot_models", "summarise_execution", "support_height"]
