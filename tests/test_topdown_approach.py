"""A top-down grasp near the top of the arm's reach: the approach ends where the hand clears the object.

bench/find_rate.py's top-down scenes (a bottle on a table, grasped 2 cm under its top) were refused
with ``motion=100``: every approach walk back from the grasp ran out of the arm's reach before the
fixed 0.15 m pre-grasp, which no IK reaches there, while the hand already cleared the bottle
(on the true shapes at 0.115 m; in the transit model, with its clearance, about 0.13 m). The
approach now ends at the first state of the walk back where the whole robot clears the transit
model, at most ``pregrasp_distance`` back. Oracle: coal on the true table and bottle against the
URDF's collision meshes (test_sensor_resolution's), at states along every joint line of the motion.
"""

from __future__ import annotations

import itertools
import math

import coal
import numpy as np
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import MotionSettings
from baseplace.placement.pipeline import object_checks
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.world.grasped_object import find_grasped_object
from conftest import tcp_by_pinocchio
from test_sensor_resolution import Oracle, _hand_links

# The TCP of a top-down grasp in front of TIAGo (base at the origin), 1.12 m up: its 0.15 m
# pre-grasp (1.27 m) is out of the walk's reach, which ends 0.13 m back, where the hand clears the bottle.
T_TCP = pose_from_xyz_rpy([0.6, -0.18, 1.12, 0.0, math.pi / 2, -3.0364])
RADIUS, HEIGHT, UNDER_TOP = 0.035, 0.22, 0.02  # the bottle; the grasp point this far under its top
SIGMA = 0.003
STATES_PER_LINE = 40


def _at(xyz) -> coal.Transform3s:
    return coal.Transform3s(np.eye(3), np.asarray(xyz, dtype=float))


@pytest.fixture(scope="module")
def topdown_scene(tiago):
    """(true shapes, noisy cloud, grasp point, the grasp's IK configuration)."""
    point = (T_TCP @ tiago.T_tcp_grasp())[:3, 3]
    top = point[2] + UNDER_TOP - HEIGHT  # the table top
    x0, x1, y0, y1 = point[0] - 0.2, point[0] + 0.4, point[1] - 0.4, point[1] + 0.4  # the table's edges
    shapes = {
        "table": (coal.Box(x1 - x0, y1 - y0, 0.04), _at([(x0 + x1) / 2, (y0 + y1) / 2, top - 0.02])),
        "bottle": (coal.Cylinder(RADIUS, HEIGHT), _at([point[0], point[1], top + HEIGHT / 2])),
    }
    X, Y = np.meshgrid(np.arange(x0, x1, 0.01), np.arange(y0, y1, 0.01))
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, top)]
    table = table[np.hypot(X.ravel() - point[0], Y.ravel() - point[1]) > RADIUS]
    a, z = np.meshgrid(
        np.linspace(0, 2 * np.pi, 24, endpoint=False), np.arange(top + 0.005, top + HEIGHT, 0.01)
    )
    side = np.c_[point[0] + RADIUS * np.cos(a).ravel(), point[1] + RADIUS * np.sin(a).ravel(), z.ravel()]
    g = np.arange(-RADIUS, RADIUS + 1e-9, 0.01)
    GX, GY = np.meshgrid(g, g)
    inside = np.hypot(GX, GY).ravel() <= RADIUS
    lid = np.c_[
        point[0] + GX.ravel()[inside], point[1] + GY.ravel()[inside], np.full(inside.sum(), top + HEIGHT)
    ]
    clean = np.concatenate([table, side, lid])
    cloud = clean + np.random.default_rng(3).normal(0.0, SIGMA, clean.shape)
    q = DampedLeastSquaresIK(tiago.arm()).solve(T_TCP, np.random.default_rng(0))
    assert q is not None
    return shapes, cloud, point, q


def test_the_fixed_pregrasp_is_out_of_reach(tiago):
    T_pre = T_TCP.copy()
    T_pre[:3, 3] -= 0.15 * T_TCP[:3, 0]  # the approach axis is the TCP's x
    assert DampedLeastSquaresIK(tiago.arm(), restarts=200).solve(T_pre, np.random.default_rng(1)) is None


def test_a_topdown_grasp_near_the_top_of_the_reach_gets_a_motion_clear_of_the_true_scene(
    tiago, topdown_scene
):
    shapes, cloud, point, q = topdown_scene
    obj = find_grasped_object(cloud, point)
    assert obj is not None
    checks = object_checks(tiago, "arm", None, cloud, obj, MotionSettings())
    motion = checks.motion.check(q, np.eye(4), T_TCP)
    assert motion is not None, checks.motion.last_contacts
    arm, oracle, hand = tiago.arm(), Oracle(tiago), _hand_links(tiago)
    retreat = float((T_TCP[:3, 3] - tcp_by_pinocchio(tiago, arm, motion.approach[0])[:3, 3]) @ T_TCP[:3, 0])
    assert 0.0 < retreat < 0.15 - 0.005  # shorter than the fixed pre-grasp, which is out of reach
    for stage, waypoints in (("transit", motion.path), ("approach", motion.approach)):
        for a, b in itertools.pairwise(waypoints):
            for f in np.linspace(0.0, 1.0, STATES_PER_LINE):
                q_full = arm.to_pinocchio(a + f * (b - a), tiago.q_reference)
                for link, what in oracle.touching(q_full, np.eye(4), shapes):
                    # only the approach's hand may touch the grasped bottle; nothing the table
                    assert stage == "approach" and what == "bottle" and link in hand, (stage, link, what)
