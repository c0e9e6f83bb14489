"""Approach restarts (MotionChecker.approach): a dev check whose walk back fails, recovered by a restart.

Table-grid dev seed 1, cell (0, 0), side grasp 5, the first verified base pose
(bench/results/motion_verdicts_s15_wide_dev.json): the walk back from the verified grasp
configuration and the first four restarts fail (approach_ik), the reference finds a motion with its
seventh restart. Checked by pinocchio FK (the approach ends on the grasp) and coal on the true
table and bottle (the execution oracle; the hand may touch the bottle only in the approach).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.geometry.poses import invert_transforms
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.placement.pipeline import PlaceSettings, scene_checks, with_floor
from baseplace.placement.scene_cache import SceneCache
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import RobotShapes, TableGridSettings, true_bottle, true_table
from conftest import tcp_by_pinocchio

T_BASE = [[-0.173648, -0.984808, 0.0, 3.475], [0.984808, -0.173648, 0.0, 1.475], [0.0, 0.0, 1.0, 0.0125],
          [0.0, 0.0, 0.0, 1.0]]  # fmt: skip
TARGET = [[-0.382683, -0.92388, 0.0, 2.861889], [0.92388, -0.382683, 0.0, 2.093433], [0.0, 0.0, 1.0, 0.889054],
          [0.0, 0.0, 0.0, 1.0]]  # fmt: skip
Q_GRASP = [0.125798, 2.244404, 0.055647, -0.558523, -0.036495, -0.376391, -0.444004, -0.202705]
OMPL_SEED = 932441364  # bench_motion_verdicts.check_seed(1, (0, 0), 5, 0)


@pytest.fixture(scope="module")
def dev_check(tiago):
    arm = tiago.arm()
    s = TableGridSettings()
    p_true, _, seen = trial_scene(1, (0, 0), s)
    points = with_floor(seen, 0.0)
    cache = SceneCache(points)
    target = np.array(TARGET)
    checks = scene_checks(tiago, arm.name, points, cache.terrain(None), target[None], PlaceSettings(), "auto",
                          cache)  # fmt: skip
    motion = checks.verifier.motion
    assert motion is not None
    oracle = ExecutionOracle(RobotShapes(tiago, arm.name), true_table(s), true_bottle(p_true, s),
                             ExecutionSettings(path_step=0.0125))  # fmt: skip
    return arm, motion.environment, motion.approach_environment, oracle, target


def test_four_restarts_find_no_approach(tiago, dev_check):
    arm, transit, approach, _, target = dev_check
    checker = MotionChecker(tiago, arm, transit, approach, MotionSettings(approach_restarts=4))
    assert checker.check(np.array(Q_GRASP), np.array(T_BASE), target, seed=OMPL_SEED) is None


def test_default_restarts_find_a_motion_free_on_the_true_scene(tiago, dev_check):
    arm, transit, approach, oracle, target = dev_check
    T_base = np.array(T_BASE)
    checker = MotionChecker(tiago, arm, transit, approach, MotionSettings())
    motion = checker.check(np.array(Q_GRASP), T_base, target, seed=OMPL_SEED)
    assert motion is not None
    reached = tcp_by_pinocchio(tiago, arm, motion.approach[-1])  # the approach ends on the grasp
    T_base_tcp = invert_transforms(T_base) @ target
    assert np.linalg.norm(reached[:3, 3] - T_base_tcp[:3, 3]) < 1e-3
    cos = 0.5 * (np.trace(reached[:3, :3] @ T_base_tcp[:3, :3].T) - 1.0)
    assert math.acos(min(1.0, cos)) < 1e-2
    for q in motion.waypoints:
        assert arm.within_limits(q)
    assert oracle.path_free(motion.path, T_base, hand_may_touch=False)
    assert oracle.path_free(motion.approach, T_base, hand_may_touch=True)
    assert np.max(np.abs(np.diff(motion.approach, axis=0))) <= checker.settings.max_joint_step
