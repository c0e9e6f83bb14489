"""The whole-edge check (issue 25 item 3): one compiled call per joint line, coal's verdict on every state.

:meth:`Environment.first_colliding_arm` certifies the states of a line by spheres in one numba call
(:func:`~baseplace.world.state_filter._uncertified_states`) and hands only what the spheres leave to
coal. The oracle is coal on every pair of every state (:meth:`Environment.colliding_arm_exact`), on
lines in a noisy table scene (the table grid's clouds): the first state it finds touching must be
the first coal finds, and a line it passes must have no state coal finds touching.
"""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import MotionChecker, MotionSettings, bisection_order, stowed_configuration
from baseplace.placement.pipeline import PlaceSettings, scene_checks, with_floor
from baseplace.placement.scene_cache import SceneCache
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.spheres import _joint_frames
from baseplace.world.environment import Environment
from baseplace.world.state_filter import sphere_cover
from baseplace.world.state_kernel import _table_gap, _uncertified_states
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import TableGridSettings
from test_state_filter import (  # the coal oracle; a geometry's extreme points
    _contacts_oracle,
    _surface_points,
)


@pytest.fixture(scope="module")
def table_lines(tiago):
    """(transit model, approach model, base pose, lines (L, 2, n)): lines near and through a noisy table."""
    s = TableGridSettings()
    _, p_est, seen = trial_scene(2, (2, 0), s)
    points = with_floor(seen, 0.0)
    cache = SceneCache(points)
    target = s.grasps(p_est, s.method_top_below)[2]
    target[2, 3] += 0.04
    arm = tiago.arm()
    checks = scene_checks(
        tiago, arm.name, points, cache.terrain(None), target[None], PlaceSettings(), "auto", cache
    )
    motion = checks.verifier.motion
    assert motion is not None and motion.approach_environment is not None
    T_base = pose_from_xyz_rpy([*(target[:2, 3] + (0.05, -0.6)), 0.0, 0.0, 0.0, 1.57])
    rng = np.random.default_rng(11)
    q_grasp = DampedLeastSquaresIK(arm, restarts=20).solve(np.linalg.inv(T_base) @ target, rng)
    assert q_grasp is not None
    starts = np.vstack([q_grasp + rng.normal(0.0, 0.15, (140, arm.n_joints)), arm.sample(rng, 20)])
    ends = starts + rng.normal(0.0, 0.3, starts.shape)
    lines = np.clip(np.stack([starts, ends], axis=1), arm.lower, arm.upper)
    return motion.environment, motion.approach_environment, T_base, lines


def test_edge_verdicts_are_coals_on_a_noisy_table(tiago, table_lines):
    transit, approach, T_base, lines = table_lines
    arm = tiago.arm()
    n = 24
    fractions = np.array(bisection_order(n), dtype=float) / n
    blocked = free = coal_blocked_only = 0
    for env in (transit, approach):
        for a, b in lines:
            Q = a + np.outer(fractions, b - a)
            first = env.first_colliding_arm(arm, Q, T_base)
            exact = [env.colliding_arm_exact(arm, q, T_base) for q in Q]
            expected = exact.index(True) if True in exact else -1
            # never "free" where coal finds a state touching, never "blocked" where coal finds none
            assert first == expected, f"edge check says state {first}, coal {expected}, line {a} -> {b}"
            blocked += first >= 0
            free += first < 0
            coal_blocked_only += first >= 0 and not exact[first]
    print(
        f"{blocked} lines blocked, {free} free, {coal_blocked_only} blocked where coal finds no state touching"
    )
    assert coal_blocked_only == 0
    assert blocked > 30 and free > 30  # both verdicts, on lines into the table and beside it
    assert transit.state_filter(arm).coal_states > 0  # states at contact reach coal


def test_motion_checker_blocks_where_a_state_by_state_check_does(tiago, table_lines):
    """MotionChecker._blocking (whole lines) returns the state the landed one-state-at-a-time loop returned."""
    transit, approach, T_base, lines = table_lines
    arm = tiago.arm()
    checker = MotionChecker(tiago, arm, transit, approach, MotionSettings())
    for a, b in lines[:60]:
        n = checker.edge_states(a, b)
        before = checker.state_checks
        expected, checked = None, 0
        for k in bisection_order(n):  # the landed loop, with coal on every pair
            checked += 1
            q = a + (b - a) * (k / n)
            if transit.colliding_arm_exact(arm, q, T_base):
                expected = q
                break
        got = checker._blocking(a, b, T_base, transit)
        assert (got is None) == (expected is None)
        if got is not None:
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
        # the max_checks budget counts the states asked: at most those the loop checked, and a itself
        assert 0 < checker.state_checks - before <= checked + 1


def test_line_checks_give_coals_verdict_at_every_state(tiago, table_lines):
    """A line's check asks few pairs at few states, yet returns what coal on every pair of every state returns.

    The oracle: coal on every pair (:meth:`Environment.colliding_arm_exact`) at each of the line's
    states in bisection order (the first touching, or none). The line check
    (:meth:`Environment.first_colliding_arm_line`) must return the same state, on lines at the
    motion check's resolution in a noisy table scene, and must have skipped states on the free ones.
    """
    transit, approach, T_base, lines = table_lines
    arm = tiago.arm()
    checker = MotionChecker(tiago, arm, transit, approach, MotionSettings())
    asked_free = states_free = blocked = 0
    for env in (transit, approach):
        for a, b in lines[::4]:
            n = checker.edge_states(a, b)
            expected = next(
                (
                    k
                    for k in bisection_order(n)
                    if env.colliding_arm_exact(arm, a + (b - a) * (k / n), T_base)
                ),
                -1,
            )
            k, asked = env.first_colliding_arm_line(
                arm, a, b, n, float(np.abs(b - a) @ checker.levers), T_base
            )
            assert k == expected, f"line check says state {k} of {n}, coal {expected}, line {a} -> {b}"
            blocked += k >= 0
            if k < 0:
                asked_free, states_free = asked_free + asked, states_free + n
    print(f"{blocked} lines blocked; free lines: {asked_free} states asked of {states_free}")
    assert blocked > 10 and states_free > 0
    assert asked_free < 0.9 * states_free  # the gaps spare states, not only pairs


def test_geometry_levers_bound_how_far_each_geometry_moves(tiago):
    """Along a joint line, no point of a robot geometry moves farther than its lever bound, nor against another.

    Oracle: pinocchio's placement of each geometry's hull points at 40 states of random lines (the
    path length, summed over the steps, at most the bound), in the arm's base frame and, for each
    pair of geometries, in the frame of the one nearer the arm's base.
    """
    from baseplace.world.state_filter import geometry_levers, hull_points

    env = Environment(tiago, {}, self_collision=False)
    arm = tiago.arm()
    filt = env.state_filter(arm)
    levers = geometry_levers(arm, filt.joint, filt.local, filt.radius)
    geom, model = env.geom, tiago.model
    data, gdata = model.createData(), pin.GeometryData(geom)
    G = len(filt.joint)
    hulls = [hull_points(geom.geometryObjects[k].geometry) for k in range(G)]
    rng = np.random.default_rng(21)
    worst, worst_pair = 0.0, 0.0
    for a, b in zip(arm.sample(rng, 12), arm.sample(rng, 12), strict=True):
        placed = []
        for t in np.linspace(0.0, 1.0, 41):
            pin.updateGeometryPlacements(
                model, data, geom, gdata, arm.to_pinocchio(a + t * (b - a), tiago.q_reference)
            )
            placed.append([np.asarray(gdata.oMg[k].homogeneous) for k in range(G)])
        dq = np.abs(b - a)
        for g in range(G):
            P = np.c_[hulls[g], np.ones(len(hulls[g]))]
            path = sum(
                np.linalg.norm((M1[g] @ P.T - M0[g] @ P.T)[:3], axis=0)
                for M0, M1 in itertools.pairwise(placed)
            )
            bound = levers[g] @ dq
            assert np.all(path <= bound + 1e-9), (g, float(path.max()), float(bound))
            worst = max(worst, float(path.max() / bound) if bound > 0 else 0.0)
        for g, h in rng.integers(G, size=(60, 2)):
            if filt.joint[g] > filt.joint[h]:
                g, h = h, g
            P = np.c_[hulls[h], np.ones(len(hulls[h]))]
            rel = [np.linalg.inv(M[g]) @ M[h] @ P.T for M in placed]  # h in g's frame
            path = sum(np.linalg.norm((r1 - r0)[:3], axis=0) for r0, r1 in itertools.pairwise(rel))
            moved = [d for d in range(arm.n_joints) if filt.joint[g] < d <= filt.joint[h]]
            bound = float(levers[h, moved] @ dq[moved]) if moved else 0.0
            assert np.all(path <= bound + 1e-9), (g, h, float(path.max()), bound)
            worst_pair = max(worst_pair, float(path.max() / bound) if bound > 0 else 0.0)
    print(f"largest path over its bound: {worst:.2f} per geometry, {worst_pair:.2f} per pair")
    assert worst > 0.3  # the bounds hold, and are not far above the moves they bound


def test_sphere_covers_hold_their_geometry(tiago):
    """Every point of every TIAGo collision geometry's hull lies in a sphere of its cover, at any configuration."""
    env = Environment(tiago, {}, self_collision=False)
    geom = env.geom
    rng = np.random.default_rng(5)
    split = 0
    for obj in geom.geometryObjects:
        C, r = sphere_cover(obj.geometry)
        P = _surface_points(obj.geometry)
        w = rng.dirichlet(np.ones(len(P)) * 0.3, size=400)  # points inside the hull, many near its faces
        inside = np.vstack([P, w @ P, *[(P[i] + P[j]) / 2 for i, j in rng.integers(len(P), size=(400, 2))]])
        gap = (np.linalg.norm(inside[:, None] - C[None], axis=2) - r).min(axis=1).max()
        assert gap <= 1e-9, f"{obj.name}: a point lies {gap} m outside its cover"
        split += len(r) > 1
    assert split > 10  # the arm's links and the hand's box are covered by several spheres
    # placed by the filter's kinematics, the cover spheres stay where pinocchio puts the geometry
    arm = tiago.arm()
    filt = env.state_filter(arm)
    starts, joints, local, radii = filt._cover
    model, data, gdata = tiago.model, tiago.model.createData(), pin.GeometryData(geom)
    T_root_armbase = filt._T_base_armbase  # base == root at the reference configuration's base frame
    covers = [sphere_cover(obj.geometry) for obj in geom.geometryObjects]
    for q in arm.sample(rng, 20):
        pin.updateGeometryPlacements(model, data, geom, gdata, arm.to_pinocchio(q, tiago.q_reference))
        F = np.empty((arm.n_joints, 3, 4))
        _joint_frames(q, arm.placements, arm.axes, arm.kinds, F, np.empty((3, 3)), np.empty(3))
        for k in range(len(starts) - 1):
            if joints[starts[k]] < 0:
                continue
            C_local, r = covers[k]
            M = env._T_root_base.inverse() * gdata.oMg[k]  # geometry in the base frame
            want = C_local @ M.rotation.T + M.translation
            j = joints[starts[k]]
            got = local[starts[k] : starts[k + 1]] @ F[j, :, :3].T + F[j, :, 3]
            got = got @ T_root_armbase[:3, :3].T + T_root_armbase[:3, 3]
            np.testing.assert_allclose(got, want, atol=1e-9)
            np.testing.assert_array_equal(radii[starts[k] : starts[k + 1]], r)


def test_self_distance_tables_never_clear_a_pair_closer_than_its_margin(tiago):
    """Where a self pair's distance table certifies a configuration, coal's distance between the meshes is above the margin."""
    env = Environment(tiago, {})
    arm = tiago.arm()
    filt = env.state_filter(arm)
    which, *tables = filt._tables
    assert (which >= 0).sum() >= 3  # the links that nearly touch at the shoulder and the wrist
    model, data, geom, gdata = filt.self_check
    rng = np.random.default_rng(8)
    cleared = 0
    for q in arm.sample(rng, 300):
        pin.forwardKinematics(model, data, arm.to_pinocchio(q, tiago.q_reference))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for p in np.flatnonzero(which >= 0):
            gap = _table_gap(q, which[p], *tables)
            if gap >= 0.0:
                cleared += 1
                pair = int(filt._self_index[p])
                distance = pin.computeDistance(geom, gdata, pair).min_distance
                # the gap: how much farther than the margin (a lower bound, used to skip states of a line)
                assert distance > gdata.collisionRequests[pair].security_margin + gap
    assert cleared > 300  # the tables do certify


def test_contacts_are_coals_on_every_pair(tiago, table_lines):
    """contacts_arm asks coal only about the pairs the spheres leave: the same contacts as coal on every pair.

    On states of the lines into and beside the table, self-collisions of random states included, in
    both models (the approach's lets the hand touch the grasped object).
    """
    transit, approach, T_base, lines = table_lines
    arm = tiago.arm()
    states = np.concatenate([lines[:, 0], lines[:, 1], lines.mean(axis=1)])[::3]
    kinds = set()
    for env in (transit, approach):
        for q in states:
            contacts = env.contacts_arm(arm, q, T_base)
            assert contacts == _contacts_oracle(env, arm, q, T_base), f"state {q}"
            kinds |= {"self" if what.startswith("self: ") else "scene" for _, what in contacts}
    assert kinds == {"self", "scene"}  # both kinds of contact met


def test_every_self_pair_the_spheres_certify_is_free_by_coal(tiago):
    """Self pairs certified by a run's group sphere, by cover pieces near the other geometry, or by a table: coal agrees.

    At random arm states and states around the stowed configuration (the arm beside the torso),
    every self pair the compiled call leaves out is one coal finds free.
    """
    arm = tiago.arm()
    env = Environment(tiago, {})
    filt = env.state_filter(arm)
    rng = np.random.default_rng(3)
    q0 = stowed_configuration(tiago, arm)
    states = np.vstack(
        [arm.sample(rng, 40), np.clip(q0 + rng.normal(0.0, 0.15, (40, arm.n_joints)), arm.lower, arm.upper)]
    )
    model, data, geom, gdata = filt.self_check
    robot_args, scene_and_self = filt._kernel_args
    P = len(filt._scene_rows)
    certified = 0
    for q in states:
        out = np.empty((1, P + len(filt._self_pairs)), dtype=np.bool_)
        q1 = np.ascontiguousarray(q[None])
        i = _uncertified_states(q1, *robot_args, np.eye(4), *scene_and_self, 0, out)
        left = out[0, P:] if i == 0 else np.zeros(len(filt._self_pairs), dtype=bool)
        pin.forwardKinematics(model, data, filt._full(q))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for p in np.flatnonzero(~left):
            pair = int(filt._self_index[p])
            assert not pin.computeCollision(geom, gdata, pair), (
                f"pair {pair} certified free, coal: touching at {q}"
            )
        certified += int((~left).sum())
    assert certified > 0.9 * len(states) * len(filt._self_pairs)


def test_a_line_too_long_for_the_gaps_table_is_checked_state_by_state(tiago, table_lines, monkeypatch):
    """Past LINE_ENTRIES gaps (states times pairs) the line's states go one by one: the same state returned."""
    import baseplace.world.state_filter as state_filter

    transit, approach, T_base, lines = table_lines
    arm = tiago.arm()
    checker = MotionChecker(tiago, arm, transit, approach, MotionSettings())
    cases = [(a, b, checker.edge_states(a, b), float(np.abs(b - a) @ checker.levers)) for a, b in lines[::8]]
    with_gaps = [transit.first_colliding_arm_line(arm, a, b, n, travel, T_base) for a, b, n, travel in cases]
    monkeypatch.setattr(state_filter, "LINE_ENTRIES", 0)
    one_by_one = [transit.first_colliding_arm_line(arm, a, b, n, travel, T_base) for a, b, n, travel in cases]
    assert [k for k, _ in one_by_one] == [k for k, _ in with_gaps]
    for (k, asked), (_, _, n, _) in zip(
        one_by_one, cases, strict=True
    ):  # every state up to the first touching
        assert asked == (n if k < 0 else bisection_order(n).index(k) + 1)
    assert any(k >= 0 for k, _ in with_gaps) and any(k < 0 for k, _ in with_gaps)
