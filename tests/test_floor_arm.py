"""The floor the base stands on: the arm and hand keep off it, the base and wheels stand on it.

The support voxels under the base are removed from the obstacles (``obstacle_voxels``), so before
no robot link was checked against the floor: find-rate dev seed 25005's reaching motion passed
TIAGo's hand through the true floor at a planner waypoint, called free. Now the removed voxels are
group ``floor``, paired with every geometry an arm's first revolute joint moves (the robot's
kinematic tree, no link names). Oracle: coal on the true floor (a box under z = 0) against the
URDF's collision meshes (test_sensor_resolution's).
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.pipeline import PlaceSettings, scene_checks
from baseplace.placement.scene_cache import SceneCache
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.world.environment import FLOOR, FLOOR_PLANE, GRASPED, Environment, arm_geometry_ids
from test_sensor_resolution import Oracle

SIGMA = 0.003
# TIAGo's arm reaching below its feet, clear of itself: hand_safety_box 0.077 m into the true floor
Q_LOW = np.array([0.069, 0.966, -1.13, -0.603, 0.643, -1.929, -0.803, -0.09])
FLOOR_BOX = (coal.Box(8.0, 8.0, 0.1), coal.Transform3s(np.eye(3), np.array([0.0, 0.0, -0.05])))


def _floor_cloud(rng, extra=None):
    g = np.arange(-1.5, 1.5, 0.02)
    X, Y = np.meshgrid(g, g)
    floor = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    clean = floor if extra is None else np.concatenate([floor, extra])
    return clean + rng.normal(0.0, SIGMA, clean.shape)


def _checks(tiago, points, target, grasped):
    cache = SceneCache(points)
    return scene_checks(
        tiago, tiago.arm().name, points, cache.terrain(None), target[None], PlaceSettings(), grasped, cache
    )


def _moved_links(tiago, oracle):
    ids = arm_geometry_ids(tiago, oracle.geom)
    return {str(tiago.model.frames[oracle.geom.geometryObjects[k].parentFrame].name) for k in ids}


def test_the_arm_moved_geometries_follow_the_kinematic_tree(tiago):
    oracle = Oracle(tiago)
    moved = _moved_links(tiago, oracle)
    everything = {str(tiago.model.frames[g.parentFrame].name) for g in oracle.geom.geometryObjects}
    # what arm_1_joint moves: the upper arm to the fingers; not the base, wheels or torso
    assert "hand_safety_box" in moved and "arm_1_link" in moved
    assert not moved & {n for n in everything if n.startswith(("base", "wheel", "caster", "torso"))}


def test_a_hand_in_the_floor_is_refused_and_the_base_on_it_is_not(tiago):
    arm, oracle = tiago.arm(), Oracle(tiago)
    T_base = np.eye(4)
    points = _floor_cloud(np.random.default_rng(0))
    target = pose_from_xyz_rpy([0.5, 0.0, 0.8, 0.0, 0.0, 0.0])
    env = _checks(tiago, points, target, None).verifier.environment
    moved = _moved_links(tiago, oracle)
    # the oracle: the hand goes into the true floor
    low = oracle.touching(arm.to_pinocchio(Q_LOW, tiago.q_reference), T_base, {"floor": FLOOR_BOX})
    assert {link for link, _ in low} & moved
    assert not Environment(tiago, {}).colliding_arm(arm, Q_LOW, T_base)  # not itself: the floor
    assert env.colliding_arm(arm, Q_LOW, T_base)
    assert ("hand_safety_box", FLOOR) in env.contacts_arm(arm, Q_LOW, T_base), env.contacts_arm(
        arm, Q_LOW, T_base
    )
    # the stowed arm: only the base, wheels and casters touch the true floor, by design; not refused
    q_home = np.array(tiago.q_reference)[arm.q_index]
    home = oracle.touching(tiago.q_reference, T_base, {"floor": FLOOR_BOX})
    assert home and not {link for link, _ in home} & moved
    assert env.contacts_arm(arm, q_home, T_base) == []
    assert not env.colliding_arm(arm, q_home, T_base)
    assert env.colliding_arm_exact(arm, Q_LOW, T_base) and not env.colliding_arm_exact(arm, q_home, T_base)
    # the compiled edge check (the state filter) agrees with coal on every pair along the line there
    line = q_home + np.linspace(0.0, 1.0, 30)[:, None] * (Q_LOW - q_home)
    exact = [k for k, q in enumerate(line) if env.colliding_arm_exact(arm, q, T_base)]
    assert exact and env.first_colliding_arm(arm, line, T_base) == exact[0]


def test_a_low_grasp_of_a_bottle_on_the_floor_is_not_blocked_twice(tiago):
    """The fine model holds the object's support (the exact plane): the floor group there is gone."""
    arm, oracle = tiago.arm(), Oracle(tiago)
    radius, height, xy = 0.035, 0.3, np.array([0.62, -0.2])
    a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 24, endpoint=False), np.arange(0.005, height, 0.01))
    side = np.c_[xy[0] + radius * np.cos(a).ravel(), xy[1] + radius * np.sin(a).ravel(), z.ravel()]
    points = _floor_cloud(np.random.default_rng(1), side)
    points = points[
        ~((np.hypot(points[:, 0] - xy[0], points[:, 1] - xy[1]) < radius - 0.005) & (points[:, 2] < 0.01))
    ]
    T_tcp = pose_from_xyz_rpy([xy[0] - 0.0, xy[1], 0.2, 0.0, 0.0, 0.0])
    T_tcp[:3, 3] -= (T_tcp @ tiago.T_tcp_grasp())[:3, 3] - [xy[0], xy[1], 0.2]  # the grasp point on the axis
    q = None
    for seed in range(5):
        q = DampedLeastSquaresIK(arm).solve(T_tcp, np.random.default_rng(seed))
        if q is not None:
            break
    assert q is not None
    shapes = {"floor": FLOOR_BOX,
              "bottle": (coal.Cylinder(radius, height), coal.Transform3s(np.eye(3), np.array([*xy, height / 2])))}  # fmt: skip
    touching = oracle.touching(arm.to_pinocchio(q, tiago.q_reference), np.eye(4), shapes)
    moved = _moved_links(tiago, oracle)
    assert not {(link, what) for link, what in touching if link in moved and what == "floor"}, touching
    assert {link for link, what in touching if what == "bottle"}  # the hand at the bottle
    checks = _checks(tiago, points, T_tcp, "auto")
    assert checks.grasped is not None
    contacts = checks.verifier.environment.contacts_arm(arm, q, np.eye(4))
    assert not [c for c in contacts if c[1] not in (GRASPED,)], contacts
    assert math.isfinite(checks.clearance)
    # the transit and approach models of the reaching motion hold the floor too, for the arm only
    motion = checks.verifier.motion
    assert motion is not None and motion.approach_environment is not None
    q_home = np.array(tiago.q_reference)[arm.q_index]
    for env in (motion.environment, motion.approach_environment):
        touched = {
            what for link, what in env.contacts_arm(arm, Q_LOW, np.eye(4)) if link == "hand_safety_box"
        }
        assert touched & {FLOOR, FLOOR_PLANE}, touched
        assert env.contacts_arm(arm, q_home, np.eye(4)) == []


@pytest.mark.parametrize("name", [FLOOR])
def test_the_floor_group_pairs_only_the_arm_moved_geometries(tiago, name):
    points = _floor_cloud(np.random.default_rng(2))
    env = _checks(tiago, points, pose_from_xyz_rpy([0.5, 0.0, 0.8, 0, 0, 0]), None).verifier.environment
    floor_ids = [g for g in env.env_ids if env.geom.geometryObjects[g].name == name]
    assert floor_ids
    paired = {int(p.first) for p in env.geom.collisionPairs if int(p.second) in floor_ids}
    assert paired == set(arm_geometry_ids(tiago, env.geom))
