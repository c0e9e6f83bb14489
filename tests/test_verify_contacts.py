"""The verification's collision check (check (3), seed 000 Alg. 2): one call for the verdict and the reason.

:meth:`Verifier.collisions` takes a candidate's verdict and its contacts from one
:meth:`Environment.contacts_arm` call. The oracle is coal on every pair: the verdict must be
:meth:`Environment.colliding_arm_exact`'s on every state, and the contacts those coal on every pair
finds (``_contacts_oracle``), on the table scenes' states near contact, at the nominal base pose and
at base poses drawn around it (the robustness score's error model), where the scene is placed anew.
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.placement.robustness import BaseErrorModel, perturbed
from baseplace.placement.verify import Verifier
from baseplace.robots.ik import DampedLeastSquaresIK
from test_state_filter import _contacts_oracle, table_scene_states


@pytest.fixture(scope="module")
def states(tiago):
    """Per scene and model: (environment, base pose, states), other states than test_state_filter's."""
    return table_scene_states(tiago, 21, every=2, pairs=80)


def _verifier(tiago, env):
    arm = tiago.arm()
    return Verifier(arm, DampedLeastSquaresIK(arm), env, np.eye(4)[None], {}, np.zeros((0, 2)))


def test_verdicts_and_contacts_are_coals_on_every_pair(tiago, states):
    arm = tiago.arm()
    total = colliding = compared = 0
    for n, (env, T_base, qs) in enumerate(states):
        verifier = _verifier(tiago, env)
        for k, q in enumerate(qs):
            contacts = verifier.collisions(q, T_base)
            exact = env.colliding_arm_exact(arm, q, T_base)
            assert (contacts is not None) == exact, f"model {n}, state {q}"
            colliding += exact
            if k % (4 if exact else 20) == 0:
                assert contacts == (_contacts_oracle(env, arm, q, T_base) or None), f"model {n}, state {q}"
                compared += 1
        total += len(qs)
    assert total >= 1000 and 0.2 * total < colliding < 0.8 * total  # both verdicts, many near contact
    assert compared >= 150


def test_verdicts_at_drawn_base_poses(tiago, states):
    """At base poses drawn around the nominal one (the scene placed anew each time), verdicts and contacts are coal's."""
    arm = tiago.arm()
    rng = np.random.default_rng(5)
    colliding = 0
    for env, T_base, qs in states:
        verifier = _verifier(tiago, env)
        poses = perturbed(T_base, BaseErrorModel(sigma_xy=0.05).sample(rng, 40))
        for T, q in zip(poses, qs[rng.choice(len(qs), len(poses))], strict=True):
            contacts = verifier.collisions(q, T)
            assert contacts == (_contacts_oracle(env, arm, q, T) or None), f"state {q} at {T[:2, 3]}"
            assert (contacts is not None) == env.colliding_arm_exact(arm, q, T)
            colliding += contacts is not None
    assert 0 < colliding < 4 * 40
