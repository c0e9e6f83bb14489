"""The straight approach's IK walk (MotionChecker.approach) near joint limits, checked by pinocchio FK."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from conftest import tcp_by_pinocchio

# A top-down grasp in front of TIAGo whose IK solution (from a seed near it) has the torso at its
# top: the retreat upwards needs the torso past its limit unless the other joints take over.
GRASP = [0.6447, -0.1792, 1.0617, 0.0, math.pi / 2, -3.0364]
Q_NEAR = [0.35, 1.1895, 0.9142, -0.0329, 1.6058, 1.5447, -0.8796, 1.1271]


@pytest.fixture(scope="module")
def torso_at_top(tiago):
    arm = tiago.arm()
    T = pose_from_xyz_rpy(GRASP)
    q = DampedLeastSquaresIK(arm, restarts=0).solve_from(T, np.array([Q_NEAR]))
    assert q is not None and q[0] == pytest.approx(arm.upper[0])  # the torso at its upper limit
    env = Environment(tiago, VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64)))
    return arm, T, q, env


def test_walk_back_from_a_grasp_with_a_joint_at_its_limit_succeeds(tiago, torso_at_top):
    arm, T, q, env = torso_at_top
    checker = MotionChecker(tiago, arm, env, settings=MotionSettings(approach_restarts=0))
    steps = checker.approach(q, T, np.eye(4))
    assert steps is not None, "the walk back from the grasp stalled at the torso's limit"
    np.testing.assert_array_equal(steps[-1], q)  # the motion ends in the verified configuration


def test_every_walk_configuration_lies_on_the_line_by_fk(tiago, torso_at_top):
    arm, T, q, env = torso_at_top
    settings = MotionSettings(approach_restarts=0)
    checker = MotionChecker(tiago, arm, env, settings=settings)
    steps = checker.approach(q, T, np.eye(4))
    assert steps is not None
    axis = T[:3, :3] @ checker.axis
    ik = DampedLeastSquaresIK(arm)
    along = []
    for qk in steps:
        assert arm.within_limits(qk)
        reached = tcp_by_pinocchio(tiago, arm, qk)
        offset = T[:3, 3] - reached[:3, 3]  # from the TCP back to the grasp: along the axis
        s = float(offset @ axis)
        along.append(s)
        assert np.linalg.norm(offset - s * axis) < ik.tol_position  # on the line
        assert -ik.tol_position <= s <= checker.pregrasp_distance + ik.tol_position
        cos = 0.5 * (np.trace(T[:3, :3] @ reached[:3, :3].T) - 1.0)
        assert math.acos(min(1.0, cos)) < ik.tol_rotation  # the grasp's orientation throughout
    assert along[0] == pytest.approx(checker.pregrasp_distance, abs=ik.tol_position)  # pre-grasp first
    assert along[-1] == pytest.approx(0.0, abs=ik.tol_position)
    assert np.all(np.diff(along) < 0)  # monotone towards the grasp
    assert np.all(np.diff(along) > -settings.approach_step - 2 * ik.tol_position)
    assert np.max(np.abs(np.diff(steps, axis=0))) <= settings.max_joint_step


@pytest.mark.parametrize("saturate, gain", [(True, 0.0), (False, 0.01), (True, 0.01)])
def test_limit_aware_ik_solutions_reach_the_pose_by_fk(tiago, saturate, gain):
    arm = tiago.arm()
    ik = DampedLeastSquaresIK(arm, restarts=10, saturate_limits=saturate, limit_gain=gain)
    rng = np.random.default_rng(7)
    solved = 0
    for q_true in arm.sample(rng, 20):
        T = tcp_by_pinocchio(tiago, arm, q_true)
        q = ik.solve(T, rng)
        if q is None:
            continue
        solved += 1
        assert arm.within_limits(q)
        reached = tcp_by_pinocchio(tiago, arm, q)
        assert np.linalg.norm(reached[:3, 3] - T[:3, 3]) < ik.tol_position
        cos = 0.5 * (np.trace(T[:3, :3] @ reached[:3, :3].T) - 1.0)
        assert math.acos(min(1.0, cos)) < ik.tol_rotation
    assert solved >= 18
