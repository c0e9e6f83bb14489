"""The hull certificate of the state filter (world/state_filter.py): every pair it clears, coal finds free.

Beyond the bounding spheres and their covers, a pair is certified by a robot geometry's convex
hull: another geometry's spheres outside one of its face planes (self pairs), every box centre near
it outside one (point parts), or all its hull's points outside one of a convex part's planes (the
exact support plane). The oracle is coal on the pair, with the pair's security margin. The states
are those of tests/test_state_filter.py: table scenes, lines along the approach, random samples and
states within a fraction of a millimetre of contact; and for the self pairs, states around the
stowed configuration (the arm beside the torso).
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from baseplace.placement.motion import stowed_configuration
from baseplace.robots.spheres import _joint_frames, _place
from baseplace.world.environment import Environment
from baseplace.world.state_filter import _distinct_planes, _edge_planes, _no_anchors
from baseplace.world.state_kernel import _hull_points_clear, _uncertified_states
from test_state_filter import table_scene_states


def _left(filt, q, T_world_armbase, hulls):
    """Per pair (scene rows, then self pairs), whether the compiled call leaves it to coal at arm state q.

    Without the self pairs' anchor fields (tests/test_anchor_fields.py tests those): what the hulls add to the spheres.
    """
    robot_args, scene_and_self = filt._kernel_args
    S, G, J = len(filt._self_pairs), len(filt.joint), len(filt._groups[1])
    scene_and_self = (*scene_and_self[:-10], *_no_anchors(S, G, J))
    if not hulls:  # the same call with no hull planes and no hull points
        G = len(filt.joint)
        empty = (np.zeros(G + 1, np.int64), np.zeros((0, 4)), np.zeros(G + 1, np.int64), np.zeros((0, 3)))
        robot_args = (*robot_args[:-4], *empty)
    out = np.empty((1, len(filt._scene_rows) + len(filt._self_pairs)), dtype=np.bool_)
    i = _uncertified_states(
        np.ascontiguousarray(q[None]), *robot_args, T_world_armbase, *scene_and_self, 0, out
    )
    return out[0] if i == 0 else np.zeros(out.shape[1], dtype=bool)


def test_hulls_clear_only_self_pairs_coal_finds_farther_than_their_margin(tiago):
    arm = tiago.arm()
    filt = Environment(tiago, {}).state_filter(arm)
    rng = np.random.default_rng(11)
    q0 = stowed_configuration(tiago, arm)
    states = np.vstack(
        [arm.sample(rng, 60), np.clip(q0 + rng.normal(0.0, 0.2, (140, arm.n_joints)), arm.lower, arm.upper)]
    )
    model, data, geom, gdata = filt.self_check
    P = len(filt._scene_rows)
    by_hulls, left_by_spheres = 0, 0
    for q in states:
        with_hulls = _left(filt, q, np.eye(4), True)[P:]
        spheres_only = _left(filt, q, np.eye(4), False)[P:]
        assert not np.any(with_hulls & ~spheres_only)  # the hulls only add certificates
        pin.forwardKinematics(model, data, filt._full(q))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for p in np.flatnonzero(spheres_only & ~with_hulls):
            pair = int(filt._self_index[p])
            distance = pin.computeDistance(geom, gdata, pair).min_distance
            assert distance > gdata.collisionRequests[pair].security_margin, f"pair {pair} at {q}"
            by_hulls += 1
        left_by_spheres += int(spheres_only.sum())
    assert by_hulls > 0.5 * left_by_spheres  # most pairs the spheres leave, the hulls clear


@pytest.fixture(scope="module")
def scene_states(tiago):
    """Per table scene and collision model (transit, approach): (environment, base pose, states (N, n))."""
    return table_scene_states(tiago, 5, every=4, pairs=40)


def test_hulls_clear_only_scene_pairs_coal_finds_free(tiago, scene_states):
    """On the table scenes, a scene pair cleared by the hulls (points or the support plane) does not touch by coal."""
    arm = tiago.arm()
    P_kinds = {"points": 0, "plane": 0}
    for env, T_base, states in scene_states:
        filt = env.state_filter(arm)
        T_world_armbase = T_base @ filt._T_base_armbase
        P = len(filt._scene_rows)
        kind = np.zeros(P, dtype=np.int64)
        for part in filt._scene_parts[0]:
            kind[part[3] : part[4]] = part[0]
        for q in states:
            with_hulls = _left(filt, q, T_world_armbase, True)[:P]
            spheres_only = _left(filt, q, T_world_armbase, False)[:P]
            assert not np.any(with_hulls & ~spheres_only)
            rows = np.flatnonzero(spheres_only & ~with_hulls)
            if len(rows) == 0:
                continue
            pairs = [int(p) for p in filt._scene_row_pair[rows]]
            touching = list(filt._scene_touching(pairs, filt._full(q), T_base))
            assert touching == [], f"pairs {touching} cleared by the hulls touch at {q}"
            P_kinds["points"] += int((kind[rows] == 0).sum())
            P_kinds["plane"] += int((kind[rows] == 1).sum())
    assert P_kinds["points"] > 100 and P_kinds["plane"] > 10, P_kinds  # both certificates at work


def test_hull_points_margin_is_below_coals_distance(tiago):
    """The margin by which one geometry's hull points clear a face plane of the other's hull is a lower bound of coal's distance.

    Every self pair, both ways, at states around the stowed configuration (the arm beside the
    torso) and random ones: wherever the test names a plane, coal's distance between the two
    geometries is at least the pair's reach plus the margin. It must also do its work: the
    torso's column and the upper arm (about 2 cm apart when the arm is tucked, where every sphere
    of the arm's cover reaches past the gap) are cleared in most states near the stowed one. The
    planes that served are handed on from state to state as the kernel hands them on, so both
    ways of finding a plane are checked: the hint, and the one the bounding centre lies
    farthest outside.
    """
    arm = tiago.arm()
    filt = Environment(tiago, {}).state_filter(arm)
    rng = np.random.default_rng(5)
    q0 = stowed_configuration(tiago, arm)
    near = np.clip(q0 + rng.normal(0.0, 0.1, (40, arm.n_joints)), arm.lower, arm.upper)
    states = np.vstack([near, arm.sample(rng, 20)])
    model, data, geom, gdata = filt.self_check
    names = [geom.geometryObjects[int(geom.collisionPairs[int(i)].first)].name + " | "
             + geom.geometryObjects[int(geom.collisionPairs[int(i)].second)].name for i in filt._self_index]  # fmt: skip
    column = names.index("torso_fixed_column_link_0 | arm_2_link_0")
    F, R, t = np.empty((arm.n_joints, 3, 4)), np.empty((3, 3)), np.empty(3)
    Cg = np.empty((len(filt.joint), 3))
    # the plane that served each pair, each way, kept as the kernel keeps them
    hints = np.full((len(filt._self_pairs), 2), -1)
    certified, column_cleared, by_hint, by_centre = 0, 0, 0, 0
    for s, q in enumerate(states):
        _joint_frames(q, arm.placements, arm.axes, arm.kinds, F, R, t)
        _place(filt.joint, filt.local, F, Cg)
        pin.forwardKinematics(model, data, filt._full(q))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for p, (g, h) in enumerate(filt._self_pairs):
            reach = float(filt._self_reach[p])
            found = [
                _hull_points_clear(a, b, reach, filt.joint, Cg, F, *filt._hulls, hints[p, w])
                for w, (a, b) in enumerate(((g, h), (h, g)))
            ]
            for w, (k, _) in enumerate(found):
                by_hint += k >= 0 and k == hints[p, w]
                by_centre += k >= 0 and k != hints[p, w]
                hints[p, w] = k if k >= 0 else hints[p, w]
            margin = max(gap for k, gap in found)
            if margin <= 0.0:
                continue
            distance = pin.computeDistance(geom, gdata, int(filt._self_index[p])).min_distance
            assert distance >= reach + margin - 1e-9, (
                f"{names[p]} at state {s}: {distance} < {reach} + {margin}"
            )
            certified += 1
            column_cleared += p == column and s < len(near)
    assert certified > 1000, certified
    assert min(by_hint, by_centre) > 100, (by_hint, by_centre)  # both ways of finding a plane at work
    assert column_cleared >= 0.9 * len(near), column_cleared


def test_edge_planes_support_the_hull_and_clear_a_link_beside_a_rim():
    """A convex part's edge planes hold its hull at or below 0, and a box they clear is as far by coal.

    A table top (1.2 x 0.8 x 0.05 m) and a 6 cm cube placed at random around its rim, turned at
    random: wherever all the cube's corners lie more than 1 cm beyond one edge plane, coal's
    distance between the two is more than 1 cm. The planes must also do their work: some cubes
    beside the rim are cleared by an edge plane and by no face plane.
    """
    V = np.array([[x, y, z] for x in (-0.6, 0.6) for y in (-0.4, 0.4) for z in (0.7, 0.75)])
    planes = _distinct_planes(ConvexHull(V).equations)
    edges = _edge_planes(V, planes)
    assert len(planes) == 6 and len(edges) == 12
    values = V @ edges[:, :3].T + edges[:, 3]
    assert np.all(values <= 1e-12) and np.all(
        (np.abs(values) <= 1e-12).sum(axis=0) == 2
    )  # each through one edge
    table, cube = coal.Box(1.2, 0.8, 0.05), coal.Box(0.06, 0.06, 0.06)
    at_table = coal.Transform3s(np.eye(3), np.array([0.0, 0.0, 0.725]))
    corners = np.array([[x, y, z] for x in (-0.03, 0.03) for y in (-0.03, 0.03) for z in (-0.03, 0.03)])
    rng = np.random.default_rng(11)
    reach, by_edges = 0.01, 0
    for _ in range(2000):
        R = Rotation.random(random_state=rng).as_matrix()
        t = np.array(
            [rng.uniform(-0.75, 0.75), rng.choice([-1, 1]) * rng.uniform(0.35, 0.5), rng.uniform(0.62, 0.8)]
        )
        C = corners @ R.T + t
        by_face = np.any(np.all(C @ planes[:, :3].T + planes[:, 3] > reach, axis=0))
        by_edge = np.any(np.all(C @ edges[:, :3].T + edges[:, 3] > reach, axis=0))
        if by_edge:
            d = coal.distance(
                cube, coal.Transform3s(R, t), table, at_table, coal.DistanceRequest(), coal.DistanceResult()
            )
            assert d > reach, f"a cube at {t} cleared by an edge plane is {d} m from the table"
            by_edges += not by_face
    assert by_edges > 50
