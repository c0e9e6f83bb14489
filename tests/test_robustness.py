from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.robustness import (
    BaseErrorModel,
    RobustnessEstimator,
    RobustnessSettings,
    perturbed,
    wilson_interval,
)
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment

TARGET = [0.0, 0.0, 0.8, 0.0, 0.0, 0.0]  # side grasp at the origin, TCP x along world x


def test_wilson_interval_matches_published_values():
    # Newcombe (1998), Table I: 81/263 -> 0.2553 to 0.3662; 0/20 -> 0 to 0.1611 (z = 1.96)
    assert wilson_interval(81, 263) == pytest.approx((0.2553, 0.3662), abs=1e-4)
    assert wilson_interval(0, 20) == pytest.approx((0.0, 0.1611), abs=1e-4)
    low, high = wilson_interval(20, 20)
    assert high == pytest.approx(1.0) and low == pytest.approx(1 - 0.1611, abs=1e-4)


def test_error_model_draws_have_the_stated_spread_and_stay_in_the_box():
    rng = np.random.default_rng(0)
    d = BaseErrorModel().sample(rng, 20_000)
    assert np.std(d[:, 0]) == pytest.approx(0.03, rel=0.03) and np.std(d[:, 1]) == pytest.approx(
        0.03, rel=0.03
    )
    assert np.std(d[:, 2]) == pytest.approx(math.radians(2), rel=0.03)
    box = BaseErrorModel("box", xy_tolerance=0.1, yaw_tolerance=0.2).sample(rng, 20_000)
    r = np.hypot(box[:, 0], box[:, 1])
    assert r.max() <= 0.1 and np.abs(box[:, 2]).max() <= 0.2
    assert np.mean(r <= 0.05) == pytest.approx(0.25, abs=0.02)  # uniform over the disc
    tight = BaseErrorModel(sigma_xy=0.2, xy_tolerance=0.05).sample(rng, 1000)  # truncated by the tolerance
    assert np.hypot(tight[:, 0], tight[:, 1]).max() <= 0.05
    with pytest.raises(InputError, match="gaussian"):
        BaseErrorModel("laplace")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="minimum"):
        RobustnessSettings(minimum=1.5)


def test_perturbed_moves_position_in_the_world_and_turns_about_the_base():
    T = pose_from_xyz_rpy([1.0, 2.0, 0.1, 0.0, 0.0, 0.5])
    P = perturbed(T, [[0.1, -0.2, 0.3]])[0]
    np.testing.assert_allclose(P[:3, 3], [1.1, 1.8, 0.1])
    np.testing.assert_allclose(P[:3, :3], pose_from_xyz_rpy([0, 0, 0, 0, 0, 0.8])[:3, :3], atol=1e-12)


def _independent_success(robot, arm, env, T_base, target, rng) -> bool:
    """Oracle: IK from random starts only (no nominal seed), pinocchio FK, full-configuration collision."""
    q = DampedLeastSquaresIK(arm, restarts=120).solve(
        np.linalg.inv(T_base) @ target, rng, arm.sample(rng, 1)[0]
    )
    if q is None:
        return False
    data = robot.model.createData()
    q_full = arm.to_pinocchio(q, robot.q_reference)
    pin.framesForwardKinematics(robot.model, data, q_full)
    base = data.oMf[robot.model.getFrameId(arm.base_frame)]
    tcp = (base.inverse() * data.oMf[robot.model.getFrameId(arm.tcp_frame)]).homogeneous
    assert np.allclose(T_base @ tcp, target, atol=2e-3)
    return not env.colliding(q_full, T_base)


def test_robustness_agrees_with_an_independent_check_and_drops_at_the_edge_of_reach(tiago):
    arm = tiago.arm()
    env = Environment(tiago, VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64)))
    target = pose_from_xyz_rpy(TARGET)
    estimator = RobustnessEstimator(arm, env, target[None], RobustnessSettings(samples=24))
    rates = []
    for distance in (0.7, 0.9):  # base behind the target along x: comfortable, then near the arm's reach
        T_base = pose_from_xyz_rpy([-distance, 0.0, 0.0, 0.0, 0.0, 0.0])
        q_nominal = DampedLeastSquaresIK(arm).solve(np.linalg.inv(T_base) @ target, np.random.default_rng(0))
        ok = estimator.successes(T_base, [q_nominal])
        rng = np.random.default_rng(7)
        oracle = np.array([_independent_success(tiago, arm, env, P, target, rng)
                           for P in perturbed(T_base, estimator.offsets)])  # fmt: skip
        assert np.mean(ok == oracle) >= 0.9, (ok, oracle)
        score = estimator.score(T_base, [q_nominal])
        assert score.samples == 24 and score.low <= score.rate <= score.high
        rates.append(score.rate)
    assert rates[0] >= 0.95 and 0.0 < rates[1] < rates[0] - 0.3, rates
    # cached: scoring the same pose again does no new IK and gives the same answer
    before = len(estimator._cache)
    assert estimator.score(pose_from_xyz_rpy([-0.7, 0, 0, 0, 0, 0])).rate == rates[0]
    assert len(estimator._cache) == before


def test_place_scores_ranks_and_filters_placements_by_robustness(tiago):
    from baseplace.placement.motion import stowed_configuration
    from baseplace.placement.pipeline import PlaceSettings, place
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.sim.scenes import Plane, Scene, SceneSettings

    rmap = build_map(tiago, None, BuildSettings(samples=3_000_000, seed=2))
    floor = Plane(0, "floor", (0.0, 0.0), (6.0, 6.0), 0.0, 0.0, 0.0, 0.0)
    points = Scene(SceneSettings(n_planes=0, extent=(6.0, 6.0), with_box=False), (floor,)).sample_cloud(
        np.random.default_rng(5), sigma=0.01
    )
    target = pose_from_xyz_rpy([1.0, 0.5, 0.75, 0.0, math.pi / 2, 0.0])
    ranked = RobustnessSettings(samples=16, rank="robustness", pool=3)
    res = place(tiago, rmap, points, target, PlaceSettings(placements=2, tries=100, robustness=ranked),
                np.random.default_rng(1))  # fmt: skip
    assert len(res.placements) == 2, dict(res.failures)
    rates = [p.robustness.rate for p in res.placements if p.robustness is not None]
    assert len(rates) == 2 and rates[0] >= rates[1]
    data = tiago.model.createData()
    arm = tiago.arm()
    for p in res.placements:
        assert p.motions is not None
        (m,) = p.motions
        np.testing.assert_allclose(m.path[0], stowed_configuration(tiago, arm))
        np.testing.assert_allclose(m.approach[-1], p.joints[0])
        pin.framesForwardKinematics(tiago.model, data, arm.to_pinocchio(p.joints[0], tiago.q_reference))
        base = data.oMf[tiago.model.getFrameId(arm.base_frame)]
        tcp = p.T_world_base @ (base.inverse() * data.oMf[tiago.model.getFrameId(arm.tcp_frame)]).homogeneous
        np.testing.assert_allclose(tcp[:3, 3], target[:3, 3], atol=2e-4)
    assert res.timings_ms["motion"] > 0 and res.timings_ms["robustness"] > 0
    strict = RobustnessSettings(samples=16, minimum=0.99)
    res = place(tiago, rmap, points, target, PlaceSettings(placements=2, tries=100, robustness=strict),
                np.random.default_rng(1))  # fmt: skip
    assert all(p.robustness is not None and p.robustness.rate >= 0.99 for p in res.placements)
    assert res.failures["robustness"] + len(res.placements) >= 1


def _stowed_tcp(robot, arm, T_base):
    """Oracle: pinocchio FK of the TCP at the stowed configuration, in the world."""
    from baseplace.placement.motion import stowed_configuration
    from conftest import tcp_by_pinocchio

    return (T_base @ tcp_by_pinocchio(robot, arm, stowed_configuration(robot, arm)))[:3, 3]


def test_a_score_with_the_reaching_motion_counts_only_draws_the_arm_can_move_from(tiago):
    """A block around the stowed hand leaves most grasp configurations free (the plain score stays
    at 0.75 of 12 draws) but no motion can start (the score with the motion is 0); in a free scene the draws with a
    motion are a subset of the plain ones, and most of them."""
    from baseplace.placement.motion import MotionChecker

    arm = tiago.arm()
    target = pose_from_xyz_rpy(TARGET)
    T_base = pose_from_xyz_rpy([-0.7, 0.0, 0.0, 0.0, 0.0, 0.0])
    q_nominal = DampedLeastSquaresIK(arm).solve(np.linalg.inv(T_base) @ target, np.random.default_rng(0))
    g = np.arange(-0.06, 0.061, 0.0125)
    block = _stowed_tcp(tiago, arm, T_base) + np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    rates = {}
    empty = VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64))
    for name, voxels in (("free", empty), ("blocked", VoxelMap.from_points(block, 0.025))):
        env = Environment(tiago, voxels)
        motion = MotionChecker(tiago, arm, env)
        plain = RobustnessEstimator(arm, env, target[None], RobustnessSettings(samples=12))
        moving = RobustnessEstimator(arm, env, target[None], RobustnessSettings(samples=12, motion=True),
                                     motion=motion)  # fmt: skip
        a, b = plain.successes(T_base, [q_nominal]), moving.successes(T_base, [q_nominal])
        assert not np.any(b & ~a), name  # the motion only takes draws away
        rates[name] = (a.mean(), b.mean())
    assert rates["free"][0] >= 0.9 and rates["free"][1] >= 0.75, rates
    assert rates["blocked"][0] >= 0.5 and rates["blocked"][1] == 0.0, rates
    with pytest.raises(InputError, match="needs the motion check"):
        RobustnessEstimator(arm, env, target[None], RobustnessSettings(samples=4, motion=True))
