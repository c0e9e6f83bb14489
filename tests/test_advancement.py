"""Certificates ahead in the state filter (conservative advancement): the positions and the marks, against brute force.

:func:`~baseplace.world.state_filter._ahead` places a batch of arm states on a line such that no
robot point moves farther between two states than their distance on it (plus a slack), from the
joints' lever arms (:func:`~baseplace.placement.motion.lever_arms`; that no point travels farther
than ``|dq| @ levers`` is tests/test_lever_arms.py). :func:`~baseplace.world.state_filter._mark`
then certifies a pair at the later states within its gap. Both are checked here against the
definitions, pair of states by pair of states; that the certified pairs are free by coal is
tests/test_edge_check.py.
"""

from __future__ import annotations

import numpy as np

from baseplace.placement.motion import MotionChecker, MotionSettings, bisection_order, lever_arms
from baseplace.world.environment import Environment
from baseplace.world.state_filter import _ahead, _mark


def _travel(Q, levers):
    """(m, m) the lever arms' bound on any robot point's travel between every two states."""
    return np.abs(Q[:, None, :] - Q[None, :, :]) @ levers


def _batches(tiago):
    arm = tiago.arm()
    env = Environment(tiago, {}, self_collision=False)
    levers = lever_arms(tiago, arm, env.geom)
    checker = MotionChecker(tiago, arm, env, None, MotionSettings(point_step=0.01))
    rng = np.random.default_rng(4)
    batches = []
    for _ in range(20):
        a, b = arm.sample(rng, 2)
        n = checker.edge_states(a, b)
        batches.append(("line", a + np.outer(np.array(bisection_order(n), dtype=float) / n, b - a)))
    batches.append(("states", arm.sample(rng, 30)))  # not one line: the travel summed in order
    a, b = arm.sample(rng, 2)
    bent = a + np.outer(np.linspace(0.0, 1.0, 40), b - a)
    bent[20] += 0.01  # one state off the line
    batches.append(("bent", bent))
    batches.append(("one", arm.sample(rng, 1)))
    batches.append(("same", np.repeat(arm.sample(rng, 1), 5, axis=0)))
    return levers, batches


def test_positions_bound_every_travel_between_two_states(tiago):
    """|s_u - s_v| + slack >= |Q_u - Q_v| @ levers for every two states; tight on a line (halved positions fail)."""
    levers, batches = _batches(tiago)
    for name, Q in batches:
        s, slack, order, rank, cert = _ahead(np.ascontiguousarray(Q), levers, 3)
        bound = _travel(Q, levers)
        assert np.all(bound <= np.abs(s[:, None] - s[None, :]) + slack), name
        assert slack < 1e-6 or name != "line"
        np.testing.assert_array_equal(s[order], np.sort(s))
        np.testing.assert_array_equal(rank[order], np.arange(len(Q)))
        assert cert.shape == (len(Q), 3) and not cert.any()
        if name == "line":  # the positions are the bound itself, not a loose one
            np.testing.assert_allclose(np.abs(s[:, None] - s[None, :]), bound, atol=1e-9)


def test_without_lever_arms_no_certificate_reaches_another_state(tiago):
    _, batches = _batches(tiago)
    Q = batches[0][1]
    s, slack, order, rank, cert = _ahead(np.ascontiguousarray(Q), None, 2)
    for i in range(len(Q)):
        _mark(cert, 1, i, 1e9, s, slack, order, rank)  # any gap
    assert not cert.any()


def test_marks_are_the_later_states_within_the_gap(tiago):
    """_mark certifies exactly the states after i whose travel bound from i is below the gap (less the slack)."""
    levers, batches = _batches(tiago)
    rng = np.random.default_rng(8)
    for name, Q in batches:
        s, slack, order, rank, cert = _ahead(np.ascontiguousarray(Q), levers, 1)
        for i in rng.integers(len(Q), size=5):
            gap = float(rng.uniform(0.0, 0.3))
            cert[:] = False
            _mark(cert, 0, int(i), gap, s, slack, order, rank)
            later = np.arange(len(Q)) > i
            expected = later & (np.abs(s - s[i]) < gap - slack)
            np.testing.assert_array_equal(cert[:, 0], expected, err_msg=name)
            # the oracle of soundness: no marked state is as far as the gap by the lever arms
            assert np.all(_travel(Q, levers)[i, cert[:, 0]] < gap), name
