from __future__ import annotations

import numpy as np
import pytest

from baseplace.robots.collision import SelfCollision


@pytest.fixture(scope="module")
def tiago_checker(tiago):
    return SelfCollision(tiago)


def test_reference_configuration_is_free(tiago, tiago_checker):
    assert not tiago_checker.colliding(tiago.q_reference)


def test_arm_folded_into_the_body_collides(tiago, tiago_checker):
    arm = tiago.arm()
    # Shoulder swung back and elbow folded: the forearm passes through the torso.
    q = np.array([0.0, 0.0, -1.5, -3.4, 2.3, 0.0, 0.0, 0.0])
    assert tiago_checker.colliding_arm(arm, q)[0]


def test_arm_pair_pruning_agrees_with_full_check(tiago, tiago_checker, rng):
    arm = tiago.arm()
    Q = arm.sample(rng, 150)
    pruned = tiago_checker.colliding_arm(arm, Q)
    full = np.array([tiago_checker.colliding(arm.to_pinocchio(q, tiago.q_reference)) for q in Q])
    np.testing.assert_array_equal(pruned, full)
    assert 0 < pruned.sum() < len(Q)


def test_pr2_uses_its_srdf(pr2):
    checker = SelfCollision(pr2)
    assert 0 < checker.n_pairs < len(checker.geom.geometryObjects) ** 2 / 2
    assert not checker.colliding(pr2.q_reference)
