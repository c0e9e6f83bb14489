"""The arm's lever arms (:func:`baseplace.placement.motion.lever_arms`), the point step's bound.

Checked against pinocchio's forward kinematics: along straight joint lines no point of any robot
geometry travels farther than sum(|dq_j| * lever_j); and kept once per robot, not per query.
"""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin

from baseplace.placement.motion import MotionChecker, MotionSettings, lever_arms
from baseplace.world.environment import Environment
from baseplace.world.state_filter import hull_points


def test_lever_arms_bound_how_far_any_point_travels(tiago):
    """Along random straight joint lines, every robot geometry's hull point travels at most sum(|dq| * lever arm)."""
    arm = tiago.arm()
    env = Environment(tiago, {})
    model, geom = env.model, env.geom
    data = model.createData()
    levers = lever_arms(tiago, arm, geom)
    objects = [o for o in geom.geometryObjects if o.parentJoint != 0]
    local = [(o.parentJoint, o.placement, hull_points(o.geometry)) for o in objects]

    def points(q_arm):
        pin.forwardKinematics(model, data, arm.to_pinocchio(q_arm, tiago.q_reference))
        out = []
        for j, M, P in local:
            oM = data.oMi[j] * M
            out.append(P @ np.asarray(oM.rotation).T + np.asarray(oM.translation))
        return np.concatenate(out)

    rng = np.random.default_rng(7)
    worst = 0.0
    for scale in (0.02, 0.3, 2.0):
        for a in arm.sample(rng, 15):
            b = np.clip(a + rng.normal(0.0, scale, arm.n_joints), arm.lower, arm.upper)
            path = [points(a + t * (b - a)) for t in np.linspace(0.0, 1.0, 41)]
            travelled = sum(np.linalg.norm(q - p, axis=1) for p, q in itertools.pairwise(path))
            bound = float(np.abs(b - a) @ levers)
            assert travelled.max() <= bound + 1e-9, f"a point travelled {travelled.max()} m, bound {bound} m"
            worst = max(worst, float(travelled.max()) / bound)
    assert worst > 0.3  # the bound is not vacuous


def test_motion_checkers_of_one_robot_share_its_lever_arms(tiago):
    """A MotionChecker per query does not recompute the lever arms (robot-only): kept, and equal to a fresh computation."""
    arm = tiago.arm()
    first, second = Environment(tiago, {}), Environment(tiago, {})
    a = MotionChecker(tiago, arm, first, settings=MotionSettings())
    b = MotionChecker(tiago, arm, second, settings=MotionSettings())
    assert a.levers is b.levers
    np.testing.assert_array_equal(b.levers, lever_arms(tiago, arm, second.geom))


def test_motion_checkers_of_one_robot_measure_its_hand_once(tiago, monkeypatch):
    """The open hand's reach (robot-only, 9 ms) is measured once per robot and arm, not per query."""
    from baseplace.placement import motion

    arm = tiago.arm()
    fresh = motion.hand_reach(tiago, arm)
    calls = []
    monkeypatch.setattr(motion, "hand_reach", lambda *a: calls.append(a) or fresh)
    monkeypatch.setattr(motion, "_KEPT", type(motion._KEPT)())  # an empty cache for this test
    checkers = [
        MotionChecker(tiago, arm, Environment(tiago, {}), settings=MotionSettings()) for _ in range(3)
    ]
    assert len(calls) == 1
    assert all(c.hand_clear_distance == fresh + motion.PREGRASP_MARGIN for c in checkers)
