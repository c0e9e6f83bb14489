"""The anchor fields of the self pairs (world/state_filter.py) bound the true distance, and certify only free pairs.

Oracles: coal's distance from a point to each true geometry of an anchor's set, placed by
pinocchio's forward kinematics; coal's collision check on every self pair
(``pin.computeCollision``). The states are those the fields serve: near the stowed configuration
(every motion starts there), along joint lines from it, random ones, and states bisected to
within a fraction of a millimetre of a self-collision.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from baseplace.placement.motion import stowed_configuration
from baseplace.robots.spheres import _joint_frames
from baseplace.world.environment import Environment
from baseplace.world.state_filter import _no_anchors
from baseplace.world.state_kernel import _anchor_bound, _uncertified_states


def _filter(tiago):
    arm = tiago.arm()
    return arm, Environment(tiago, {}).state_filter(arm)


def _frames(arm, q):
    """(n, 3, 4) the arm joints' frames in the arm's base frame at arm state q (the kernel's FK)."""
    F = np.empty((arm.n_joints, 3, 4))
    _joint_frames(
        np.ascontiguousarray(q, dtype=float),
        arm.placements,
        arm.axes,
        arm.kinds,
        F,
        np.empty((3, 3)),
        np.empty(3),
    )
    return F


def _members(filt, a):
    """The geometries of anchor a: the first geometry of each self pair the anchor serves."""
    anchor_of = filt._anchors[0]
    return sorted({int(g) for g in filt._self_pairs[anchor_of == a, 0]})


def _self_colliding(filt, q):
    model, data, geom, gdata = filt.self_check
    pin.forwardKinematics(model, data, filt._full(q))
    pin.updateGeometryPlacements(model, data, geom, gdata)
    return any(pin.computeCollision(geom, gdata, int(p)) for p in filt._self_index)


def test_anchor_fields_bound_coals_distance_to_their_geometries(tiago):
    """At points near and around each anchor's geometries, the field's bound is at most coal's distance to every one."""
    arm, filt = _filter(tiago)
    frames = filt._anchors[1]
    assert list(frames) == [-1, 0]
    model, data, geom, gdata = filt.self_check
    rng = np.random.default_rng(5)
    q = stowed_configuration(tiago, arm)
    q[0] = arm.upper[0]  # the torso raised: joint 0's frame away from the base's
    F = _frames(arm, q)
    pin.forwardKinematics(model, data, filt._full(q))
    pin.updateFramePlacements(model, data)
    pin.updateGeometryPlacements(model, data, geom, gdata)
    T_root_armbase = data.oMf[model.getFrameId(arm.base_frame)]
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    point = coal.Sphere(1e-9)
    worst, tight = np.inf, 0
    for a in range(len(frames)):
        members = _members(filt, a)
        assert len(members) >= 4
        # points near the true geometries (their vertices pushed out 0-4 cm) and across the field's box
        near = []
        for g in members:
            M = T_root_armbase.inverse() * gdata.oMg[g]
            V = _geometry_points(geom.geometryObjects[g].geometry)
            V = V[rng.integers(len(V), size=min(len(V), 150))] @ M.rotation.T + M.translation
            d = rng.normal(size=V.shape)
            near.append(
                V + d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.0, 0.04, (len(V), 1))
            )
        box = filt._anchors[2][a]
        spread = rng.uniform(box[:3] - 0.2, box[3:] + 0.2, (600, 3))
        for c in np.vstack([*near, spread]):  # c in the arm's base frame
            bound = _anchor_bound(c, a, F, *filt._anchors[1:8])
            c_root = T_root_armbase.act(c)
            true = np.inf
            for g in members:
                result.clear()
                M = gdata.oMg[g]
                true = min(true, coal.distance(point, coal.Transform3s(np.eye(3), c_root),
                                               geom.geometryObjects[g].geometry, coal.Transform3s(M.rotation, M.translation),
                                               request, result))  # fmt: skip
            worst = min(worst, max(true, 0.0) - bound)  # coal: negative inside (a depth)
            tight += bool(0.0 < true < 0.05 and bound > true - 0.02)
    assert worst >= -1e-6, f"an anchor field bound exceeds coal's distance by {-worst} m"
    assert tight >= 100  # the bound is near the truth close to the geometries, where it serves


def _geometry_points(geometry):
    if isinstance(geometry, coal.BVHModelBase):
        return np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)
    if isinstance(geometry, coal.ConvexBase):
        return np.asarray(geometry.points(), dtype=float).reshape(-1, 3)
    geometry.computeLocalAABB()
    lo, hi = np.asarray(geometry.aabb_local.min_), np.asarray(geometry.aabb_local.max_)
    return np.random.default_rng(0).uniform(lo, hi, (200, 3))


def _left(filt, q, anchors, hulls=True):
    """Per self pair, whether the compiled call leaves it to coal at arm state q (with or without the anchor fields, the hulls)."""
    robot_args, scene_and_self = filt._kernel_args
    if not hulls:  # no hull planes, no hull points: what the spheres and the fields alone certify
        G = len(filt.joint)
        empty = (np.zeros(G + 1, np.int64), np.zeros((0, 4)), np.zeros(G + 1, np.int64), np.zeros((0, 3)))
        robot_args = (*robot_args[:-4], *empty)
    if not anchors:
        S, G, J = len(filt._self_pairs), len(filt.joint), len(filt._groups[1])
        scene_and_self = (*scene_and_self[:-10], *_no_anchors(S, G, J))
    P = len(filt._scene_rows)
    out = np.empty((1, P + len(filt._self_pairs)), dtype=np.bool_)
    i = _uncertified_states(np.ascontiguousarray(q[None]), *robot_args, np.eye(4), *scene_and_self, 0, out)
    return out[0, P:] if i == 0 else np.zeros(len(filt._self_pairs), dtype=bool)


def _stowed_states(tiago, arm, filt, rng):
    """States near the stowed configuration, along joint lines from it, random, and bisected to self-contact."""
    q0 = stowed_configuration(tiago, arm)
    near = np.clip(q0 + rng.normal(0.0, 0.15, (250, arm.n_joints)), arm.lower, arm.upper)
    far = arm.sample(rng, 100)
    lines = np.vstack([q0 + (b - q0) * t for b in far[:10] for t in np.linspace(0.0, 1.0, 15)])
    states = np.vstack([near, lines, far])
    hit = np.array([_self_colliding(filt, q) for q in states])
    free, touch = states[~hit], states[hit]
    assert len(touch) >= 20 and len(free) >= 20
    bisected = []
    for _ in range(60):  # from a free state near the stowed one to a self-colliding one
        a, b = free[rng.integers(len(free))], touch[rng.integers(len(touch))]
        for _ in range(12):
            m = (a + b) / 2
            if _self_colliding(filt, m):
                b = m
            else:
                a = m
        bisected += [a, b]
    return np.vstack([states, bisected])


def test_anchor_fields_certify_only_self_pairs_coal_finds_free(tiago):
    arm, filt = _filter(tiago)
    model, data, geom, gdata = filt.self_check
    states = _stowed_states(tiago, arm, filt, np.random.default_rng(17))
    by_anchor, colliding, anchored = 0, 0, filt._anchors[0] >= 0
    for q in states:
        pin.forwardKinematics(model, data, filt._full(q))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        touching = np.array([pin.computeCollision(geom, gdata, int(p)) for p in filt._self_index])
        colliding += bool(touching.any())
        for hulls in (True, False):
            left = _left(filt, q, True, hulls)
            wrong = np.flatnonzero(touching & ~left)
            assert len(wrong) == 0, (
                f"pairs {filt._self_index[wrong]} certified free at {q}, coal finds them touching"
            )
        by_anchor += int((_left(filt, q, False, False) & ~left & anchored).sum())
    assert colliding >= 60  # the states reach self-contact
    assert by_anchor >= 2000  # with no hulls, the fields certify pairs the spheres leave to coal
