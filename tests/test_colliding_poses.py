"""The batched check over base poses (StateFilter.colliding_poses) gives coal's verdict on every pair.

The robustness score checks each error draw's IK configuration at the draw's own base pose
(placement/robustness.py): many (arm state, base pose) pairs, each at a pose the state filter has
not seen, with the geometries no arm joint moves placed for all poses at once. The oracle is
:meth:`Environment.colliding_arm_exact` (coal on every pair) on the table-grid scenes of
tests/test_state_filter.py: random pairs from base poses spread around the scene's pose (many with the
base or torso in the table) and pairs within a fraction of a millimetre of contact, found by
bisecting (state, pose offset) between free and colliding pairs.
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.placement.motion import stowed_configuration
from baseplace.placement.robustness import BaseErrorModel, RobustnessEstimator, RobustnessSettings, perturbed
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.world.environment import Environment
from baseplace.world.state_filter import StateFilter
from test_state_filter import SCENES, _environments, _states, scene_models


def _pair_set(env, arm, T_base, states, rng, random=300, pairs=60, depth=12):
    """(Q (N, n), T (N, 4, 4), coal's verdicts (N,)): random pairs, then bisected pairs near contact."""
    offsets = rng.normal(0.0, 1.0, (random, 3)) * (0.2, 0.2, 0.5)
    Q = states[rng.integers(len(states), size=random)]
    exact = np.array(
        [env.colliding_arm_exact(arm, q, T) for q, T in zip(Q, perturbed(T_base, offsets), strict=True)]
    )
    free, hit = np.flatnonzero(~exact), np.flatnonzero(exact)
    assert len(free) and len(hit)
    out_q, out_d = list(Q), list(offsets)
    for _ in range(pairs):
        a, b = free[rng.integers(len(free))], hit[rng.integers(len(hit))]
        (qa, da), (qb, db) = (Q[a], offsets[a]), (Q[b], offsets[b])
        for _ in range(depth):
            qm, dm = (qa + qb) / 2, (da + db) / 2
            if env.colliding_arm_exact(arm, qm, perturbed(T_base, dm)[0]):
                qb, db = qm, dm
            else:
                qa, da = qm, dm
        out_q += [qa, qb]
        out_d += [da, db]
    Q, T = np.array(out_q), perturbed(T_base, np.array(out_d))
    exact = np.concatenate(
        [exact, [env.colliding_arm_exact(arm, q, t) for q, t in zip(Q[random:], T[random:], strict=True)]]
    )
    return Q, T, exact


@pytest.fixture(scope="module")
def pose_pairs(tiago):
    """Per table scene and collision model (transit, approach): (environment, Q, T, coal's verdicts)."""
    rng = np.random.default_rng(11)
    arm = tiago.arm()
    return [
        (env, *_pair_set(env, arm, T_base, states, rng)) for env, T_base, states in scene_models(tiago, rng)
    ]


def test_batched_verdicts_are_coals(tiago, pose_pairs):
    arm = tiago.arm()
    total, colliding, static_left = 0, 0, 0
    for env, Q, T, exact in pose_pairs:
        f = env.state_filter(arm)
        fast = env.colliding_arm_poses(arm, Q, T)
        wrong = np.flatnonzero(fast != exact)
        assert len(wrong) == 0, (
            f"{len(wrong)} of {len(Q)} verdicts differ from coal's, first at pair {wrong[0]}"
        )
        assert np.array_equal(fast, [env.colliding_arm(arm, q, t) for q, t in zip(Q, T, strict=True)])
        total += len(Q)
        colliding += int(exact.sum())
        static_left += sum(bool(x) for x in f._static_uncertified(T @ f._T_base_armbase))
    assert total >= 1500
    assert 0.2 * total < colliding < 0.8 * total  # both verdicts, many pairs at contact
    assert static_left > 0  # the geometries no arm joint moves leave pairs to coal at some poses


def test_a_pose_off_by_one_is_caught(tiago, pose_pairs, monkeypatch):
    """The oracle comparison catches a batch whose static geometries are placed by the neighbouring draw's pose."""
    arm = tiago.arm()
    right = StateFilter._static_uncertified
    monkeypatch.setattr(
        StateFilter, "_static_uncertified", lambda self, T: right(self, np.roll(T, 1, axis=0))
    )
    wrong = sum(int(np.sum(env.colliding_arm_poses(arm, Q, T) != exact)) for env, Q, T, exact in pose_pairs)
    assert wrong > 0


def test_one_state_per_pose(tiago, pose_pairs):
    env, Q, T, _ = pose_pairs[0]
    arm = tiago.arm()
    assert env.colliding_arm_poses(arm, Q[:0], T[:0]).shape == (0,)
    with pytest.raises(InputError):
        env.colliding_arm_poses(arm, Q[:3], T[:2])
    with pytest.raises(InputError):
        env.colliding_arm_poses(arm, Q[:1], T[0])


@pytest.fixture()
def bare(tiago):
    """(environment with no obstacles, arm, two arm states (2, n), two base poses (2, 4, 4)): cheap inputs to refuse."""
    arm = tiago.arm()
    Q = np.stack([stowed_configuration(tiago, arm)] * 2)
    return Environment(tiago, {}), arm, Q, np.stack([np.eye(4)] * 2)


def _refusal(env, arm, Q, T) -> str:
    """The one-line message of the InputError that colliding_arm_poses raises on (Q, T)."""
    with pytest.raises(InputError) as caught:
        env.colliding_arm_poses(arm, Q, T)
    message = str(caught.value)
    assert message and "\n" not in message
    return message


def test_refuses_a_count_mismatch(bare):
    env, arm, Q, T = bare
    message = _refusal(env, arm, np.vstack([Q, Q[:1]]), T)
    assert f"one arm state ({arm.n_joints},) per base pose, got (3, {arm.n_joints}) for 2 poses" in message


def test_refuses_a_wrong_number_of_joints(bare):
    env, arm, Q, T = bare
    message = _refusal(env, arm, Q[:, :-1], T)
    assert f"one arm state ({arm.n_joints},) per base pose, got (2, {arm.n_joints - 1})" in message


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_refuses_a_non_finite_pose(bare, bad):
    env, arm, Q, T = bare
    T = T.copy()
    T[1, 0, 3] = bad
    assert "base poses must be finite: 1 of 2 are not, first at 1" in _refusal(env, arm, Q, T)


@pytest.mark.parametrize("shape", [(4, 4), (2, 3, 4), (2, 4, 3), (1, 2, 4, 4)])
def test_refuses_a_wrong_pose_shape(bare, shape):
    env, arm, Q, _ = bare
    message = _refusal(env, arm, Q[: shape[0]], np.zeros(shape))
    assert f"base poses must be (S, 4, 4) matrices, got shape {shape}" in message


def test_robustness_draws_get_coals_verdicts(tiago):
    """The score's draws equal an independent reference: each draw's IK solution, coal on every pair at the draw's pose.

    Wide base errors on a table scene (many draws put the base or the arm in the table), one IK
    solution per draw (the default; a second one from a random start would hide most wrong
    verdicts). The reference solves the same batched IK (the estimator's restarts and random
    stream, ``seed + 1``) and asks :meth:`Environment.colliding_arm_exact` draw by draw.
    """
    scene_seed, cell, grasp, offset, yaw = SCENES[0]
    target, _, env = _environments(
        tiago, scene_seed, cell, grasp
    )  # the approach model: the hand may touch the object
    arm = tiago.arm()
    T_base, _ = _states(tiago, target, offset, yaw, np.random.default_rng(3))
    q_seed = DampedLeastSquaresIK(arm, restarts=20).solve(
        np.linalg.inv(T_base) @ target, np.random.default_rng(4)
    )
    settings = RobustnessSettings(samples=64, error=BaseErrorModel(sigma_xy=0.12, sigma_yaw=0.4))
    estimator = RobustnessEstimator(arm, env, target[None], settings)
    ok = estimator.successes(T_base, [q_seed])
    poses = perturbed(T_base, estimator.offsets)
    ik = DampedLeastSquaresIK(arm, restarts=settings.ik_restarts)
    q, found = ik.solve_batch(np.linalg.inv(poses) @ target, np.random.default_rng(settings.seed + 1), q_seed)
    reference = np.array(
        [
            bool(f) and not env.colliding_arm_exact(arm, qi, T)
            for qi, f, T in zip(q, found, poses, strict=True)
        ]
    )
    assert 5 < reference.sum() < len(reference) - 5  # draws on both sides
    np.testing.assert_array_equal(ok, reference)
