"""The execution oracle (baseplace_experiments/execution.py) and the collision-aware robustness score."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.robustness import RobustnessEstimator, RobustnessSettings
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.table_grid import RobotShapes, TrueShape
from conftest import tcp_by_pinocchio

GRASP = pose_from_xyz_rpy([0.75, -0.15, 0.85, 0.0, 0.0, 0.0])  # side grasp in front of the base


def _box(name: str, lo, hi) -> TrueShape:  # type: ignore[no-untyped-def]
    a, b = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    T = np.eye(4)
    T[:3, 3] = (a + b) / 2
    return TrueShape(name, coal.Box(*(b - a)), T)


@pytest.fixture(scope="module")
def shapes(tiago):
    return RobotShapes(tiago)


def test_oracle_solutions_reach_the_grasp_and_clear_a_low_table(tiago, shapes):
    table = _box("table", (0.6, -0.6, 0.0), (1.2, 0.6, 0.7))
    oracle = ExecutionOracle(shapes, [table], None, ExecutionSettings(ik_solutions=8))
    found = oracle.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0))
    assert found
    for q in found:  # pinocchio FK and a direct coal query, outside the oracle
        np.testing.assert_allclose(tcp_by_pinocchio(tiago, tiago.arm(), q), GRASP, atol=2e-3)
        assert shapes.touching(q, np.eye(4), [table]) is None


def test_oracle_finds_nothing_when_the_grasp_is_inside_a_block_or_out_of_reach(tiago, shapes):
    block = _box("block", (0.6, -0.6, 0.0), (1.2, 0.6, 1.0))  # the grasp point is inside it
    oracle = ExecutionOracle(shapes, [block], None, ExecutionSettings(ik_solutions=8))
    assert oracle.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0)) == []
    free = ExecutionOracle(shapes, [], None, ExecutionSettings(ik_solutions=8))
    far = pose_from_xyz_rpy([-1.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # 2.25 m behind the grasp
    assert free.grasp_rate(far, GRASP, np.zeros((4, 3)), np.random.default_rng(0)) == 0.0
    assert free.grasp_rate(np.eye(4), GRASP, np.zeros((2, 3)), np.random.default_rng(0)) == 1.0


def test_oracle_path_check_sees_a_wall_between_two_free_configurations(tiago, shapes):
    arm = tiago.arm()
    free = ExecutionOracle(shapes, [], None)
    q = free.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0), limit=1)[0]
    # a thin wall just behind the grasp's hand, between the stowed arm and the grasp
    p = tcp_by_pinocchio(tiago, arm, q)[:3, 3]
    wall = _box("wall", (p[0] - 0.25, -1.0, 0.0), (p[0] - 0.23, 1.0, 1.6))
    walled = ExecutionOracle(shapes, [wall], None)
    path = np.array([free.q_stowed, q])
    assert free.path_free(path, np.eye(4), hand_may_touch=False)
    assert not walled.path_free(path, np.eye(4), hand_may_touch=False)


def test_execution_settings_are_checked():
    with pytest.raises(InputError, match="ik_solutions"):
        ExecutionSettings(ik_solutions=0)
    with pytest.raises(InputError, match="path_step"):
        ExecutionSettings(path_step=-1.0)
    with pytest.raises(InputError, match="ik_solutions"):
        RobustnessSettings(ik_solutions=0)


def test_more_ik_solutions_per_draw_never_lose_a_draw_and_agree_with_the_oracle(tiago, shapes):
    """A low table under the grasp: some IK branches put the elbow into it. Each draw the scorer
    counts with 8 solutions must have a collision-free solution by the oracle (true box)."""
    arm = tiago.arm()
    lo, hi = np.array([0.55, -0.8, 0.0]), np.array([1.3, 0.8, 0.72])
    g = [np.arange(a, b + 1e-9, 0.02) for a, b in zip(lo, hi, strict=True)]
    pts = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    env = Environment(tiago, VoxelMap.from_points(pts, 0.025))
    T_base = pose_from_xyz_rpy([0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    one = RobustnessEstimator(arm, env, GRASP[None], RobustnessSettings(samples=24, ik_solutions=1))
    eight = RobustnessEstimator(arm, env, GRASP[None], RobustnessSettings(samples=24, ik_solutions=8))
    ok1, ok8 = one.successes(T_base), eight.successes(T_base)
    assert ok8.sum() > ok1.sum()  # 24 vs 18 draws here: the first IK branch is not the only one
    oracle = ExecutionOracle(
        shapes, [_box("table", lo - 0.0125, hi + 0.0125)], None, ExecutionSettings(ik_solutions=32)
    )
    from baseplace.placement.robustness import perturbed

    poses = perturbed(T_base, eight.offsets)
    agree = [bool(oracle.grasp_configurations(P, GRASP, np.random.default_rng(k), limit=1)) == bool(s)
             for k, (P, s) in enumerate(zip(poses, ok8, strict=True))]  # fmt: skip
    assert np.mean(agree) >= 0.85, (ok8, agree)


def test_the_robots_object_points_are_those_the_table_grid_drops():
    from baseplace_experiments.execution_experiment import _kept_rows
    from baseplace_experiments.table_grid import TableGridSettings, object_cloud, table_cloud, without_object

    s = TableGridSettings()
    p = s.cell_centre(1, 2)
    cloud = np.concatenate([table_cloud(s), object_cloud(p, s)])
    estimate = p + np.array([0.01, -0.01, 0.0])
    kept = _kept_rows(cloud, estimate, s)
    np.testing.assert_array_equal(cloud[kept], without_object(cloud, estimate, s))
    assert 0 < len(cloud) - len(kept) < len(object_cloud(p, s)) + 200


@pytest.mark.slow
def test_execution_trial_runs_every_method_on_the_same_draws(tiago, tiago_map, shapes):
    from baseplace_experiments.execution_experiment import (
        EXECUTION_METHODS,
        execution_trial,
        summarise_execution,
    )

    out = execution_trial(
        tiago, tiago_map, shapes, 0, (1, 0), RobustnessSettings(samples=16, pool=3), draws=2
    )
    assert set(out["methods"]) == set(EXECUTION_METHODS)
    for entry in out["methods"].values():
        assert len(entry["outcomes"]) == 2
        assert set(entry["outcomes"]) <= {"ok", "no_grasp", "no_motion", "motion_collision", "no_placement"}
        assert entry["success"] == entry["outcomes"].count("ok")
    summary = summarise_execution([out])
    assert all(summary[m]["draws"] == 2 for m in EXECUTION_METHODS)


def test_the_bottle_is_cut_at_the_measured_table_top_when_the_estimate_is_high():
    from baseplace_experiments.execution_experiment import _kept_rows, support_height
    from baseplace_experiments.table_grid import TableGridSettings, object_cloud, table_cloud

    s = TableGridSettings()
    p = s.cell_centre(0, 0)
    rng = np.random.default_rng(3)
    bottle = object_cloud(p, s)
    cloud = np.concatenate([table_cloud(s), bottle])
    seen = cloud + rng.normal(0.0, s.cloud_sigma, cloud.shape)
    estimate = p + np.array([0.005, -0.004, 0.012])  # 1.2 cm high, as v1's failing held-out trial
    z = support_height(seen, estimate, s)
    assert abs(z - s.table_height) < 0.003  # the generator's table top, not the estimate's bottom
    is_bottle = np.arange(len(seen)) >= len(cloud) - len(bottle)
    # what stays an obstacle around the bottle must not rise above the true table top by more than
    # the 5 mm margin and the support height's error (3 mm); the estimate's cut leaves its foot
    foot = is_bottle & (seen[:, 2] > s.table_height + 0.008)
    for bottom, leaves_foot in ((z, False), (None, True)):
        kept = np.zeros(len(seen), dtype=bool)
        kept[_kept_rows(seen, estimate, s, bottom)] = True
        assert bool((kept & foot).any()) == leaves_foot
    far = ~is_bottle & (np.hypot(*(cloud[:, :2] - p[:2]).T) > s.object_width / 2 + s.hand_clearance + 0.02)
    kept = np.zeros(len(seen), dtype=bool)
    kept[_kept_rows(seen, estimate, s, z)] = True
    assert kept[far].all()  # the table away from the bottle stays an obstacle


class _RecordingPlanner:
    """The robot's motion planner (a real :class:`MotionChecker` on the robot's own voxels), recording its goals."""

    def __init__(self, robot, voxels):  # type: ignore[no-untyped-def]
        from baseplace.placement.motion import MotionChecker

        self.checker = MotionChecker(robot, robot.arm(), Environment(robot, voxels))
        self.goals: list[tuple[np.ndarray, np.ndarray]] = []

    def __getattr__(self, name):  # type: ignore[no-untyped-def]
        return getattr(self.checker, name)

    def check(self, q_grasp, T_world_base, T_world_tcp, seed=0):  # type: ignore[no-untyped-def]
        self.goals.append((np.asarray(q_grasp, dtype=float), np.asarray(T_world_tcp, dtype=float)))
        return self.checker.check(q_grasp, T_world_base, T_world_tcp, seed)


def _far_voxels():  # type: ignore[no-untyped-def]
    return VoxelMap.from_points(np.array([[5.0, 5.0, 0.1]]), 0.025)  # nothing near the robot


def test_the_robot_plans_to_its_own_ik_solution_not_the_oracles(tiago, shapes):
    """The robot sees no obstacle at its elbow; the true scene has one. The robot must plan to the
    IK solution it finds on its own model from its own first start (stowed), and the oracle must
    then see the executed motion touch the true obstacle. Handing the planner the oracle's
    solution (free on the true scene) would dodge the obstacle the robot never saw."""
    from baseplace.robots.ik import DampedLeastSquaresIK

    arm = tiago.arm()
    oracle = ExecutionOracle(shapes, [], None, ExecutionSettings(ik_solutions=16))
    q_own = DampedLeastSquaresIK(arm, restarts=0).solve_from(GRASP, oracle.q_stowed[None])
    assert q_own is not None
    data = tiago.model.createData()
    pin.forwardKinematics(tiago.model, data, arm.to_pinocchio(q_own, tiago.q_reference))
    elbow = data.oMi[tiago.model.getJointId(arm.joint_names[4])].translation
    block = _box("block", elbow - 0.04, elbow + 0.04)
    assert shapes.touching(q_own, np.eye(4), [block]) is not None
    truth = ExecutionOracle(shapes, [block], None, ExecutionSettings(ik_solutions=16))
    planner = _RecordingPlanner(tiago, _far_voxels())
    outcome = truth.execute(np.eye(4), GRASP[None], planner, np.random.default_rng(0))
    assert planner.goals, outcome
    np.testing.assert_allclose(planner.goals[0][0], q_own, atol=1e-9)
    assert outcome == "motion_collision"


def test_every_method_tries_the_grasps_in_one_order_nearest_first(tiago, shapes):
    """One grasp-selection rule: whatever order a method hands the grasps in, the robot tries the
    one nearest its base first."""
    near = pose_from_xyz_rpy([0.6, -0.15, 0.85, 0.0, 0.0, 0.0])  # 0.15 m nearer than GRASP
    oracle = ExecutionOracle(shapes, [], None, ExecutionSettings(ik_solutions=8))
    assert oracle.grasp_configurations(np.eye(4), near, np.random.default_rng(0), limit=1)  # both reachable
    assert oracle.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0), limit=1)
    for grasps in (np.stack([GRASP, near]), np.stack([near, GRASP])):
        planner = _RecordingPlanner(tiago, _far_voxels())
        assert oracle.execute(np.eye(4), grasps, planner, np.random.default_rng(0)) == "ok"
        np.testing.assert_allclose(planner.goals[0][1], near)


def test_protocol_v5_gives_the_robot_the_products_scene_model(tiago):
    """v5's robot models are those ``candidates`` builds from the same noisy cloud: the table plane
    the bottle stands on exact, a clearance from its noise, the bottle found by the product (only
    the hand may touch it); v4's ("slab") are 25 mm voxels with no plane and no clearance."""
    from baseplace.placement.pipeline import object_checks
    from baseplace.world.grasped_object import find_grasped_object
    from baseplace_experiments.execution_experiment import robot_models, trial_scene
    from baseplace_experiments.table_grid import TableGridSettings

    s = TableGridSettings()
    _, p_est, seen = trial_scene(0, (0, 0), s)
    env, planner, slab = robot_models(tiago, "arm", seen, p_est, s, support="product")
    product = object_checks(tiago, "arm", None, seen, find_grasped_object(seen, p_est), planner.settings)
    assert slab is None
    assert "support_plane" in env.obstacle_names and product.environment.obstacle_names == env.obstacle_names
    assert 0.003 <= env.clearance == pytest.approx(product.environment.clearance)
    assert planner.approach_environment is not None and planner.approach_environment.hand_ids
    v4, _, _ = robot_models(tiago, "arm", seen, p_est, s, support="slab")
    assert v4.clearance == 0.0 and v4.obstacle_names != env.obstacle_names

    def finest(e):  # the finest cells [m] of the environment's octrees
        return min(t.getResolution() for t in e.obstacle_trees)

    assert finest(env) == pytest.approx(0.00125) and finest(v4) >= 0.005  # smooth surfaces at 1.25 mm
    with pytest.raises(ValueError, match="voxels, slab, product"):
        from baseplace_experiments.execution_experiment import execution_trial

        execution_trial(tiago, None, None, 0, (0, 0), RobustnessSettings(), support="plane")  # type: ignore[arg-type]
