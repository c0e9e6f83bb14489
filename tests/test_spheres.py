"""The sphere self-collision model against the exact coal check (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.robots.collision import SelfCollision
from baseplace.robots.model import Robot
from baseplace.robots.spheres import SphereModel


@pytest.mark.parametrize("name", ["tiago", "tiago_dual"])  # dual: the other arm at its reference
def test_sphere_model_misses_few_coal_collisions(name: str) -> None:
    robot = Robot(name)
    arm = robot.arm()
    model = SphereModel(robot)
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(2024), 1000)  # not the calibration seed
    coal = exact.colliding_arm(arm, Q)
    fast = model.colliding_arm(arm, Q)
    assert 0.05 < coal.mean() < 0.5  # the sample holds collisions to miss
    false_free = float((coal & ~fast).mean())
    false_colliding = float((~coal & fast).mean())
    assert false_free <= 0.005, false_free
    assert false_colliding <= 0.2, false_colliding


def test_build_with_self_collision_drops_samples(tmp_path) -> None:
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.storage import load_map, save_map

    robot = Robot("tiago")
    m = build_map(robot, settings=BuildSettings(samples=20_000, self_collision=True))
    assert 0.05 * 20_000 < m.info.dropped_self_collision < 0.5 * 20_000
    assert int(m.counts.sum()) == 20_000 - m.info.dropped_self_collision
    assert m.info.self_collision_checker.startswith("spheres-2: ")  # provenance of the drops
    save_map(m, tmp_path / "m.rmap")
    assert load_map(tmp_path / "m.rmap", robot).info == m.info  # the file keeps it


def test_bounding_hierarchy_is_exact_for_the_sphere_pairs() -> None:
    """The kernel's bounds only skip work: its verdict is that of every checked sphere pair.

    Oracle: sphere centres from pinocchio's joint placements and a brute-force test of all of
    ``sphere_pairs``.
    """
    import pinocchio as pin

    robot = Robot("tiago")
    arm = robot.arm()
    model = SphereModel(robot)
    Q = arm.sample(np.random.default_rng(31), 400)
    fast = model.colliding_arm(arm, Q)
    data = robot.model.createData()
    base = robot.model.getFrameId(arm.base_frame)
    ids = [robot.model.getJointId(j) for j in arm.joint_names]
    u, v = model.sphere_pairs[:, 0], model.sphere_pairs[:, 1]
    r = model.sphere_radius[u] + model.sphere_radius[v]
    brute = np.empty(len(Q), dtype=bool)
    for i, q in enumerate(Q):
        pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio(q, robot.q_reference))
        base_inv = data.oMf[base].inverse()
        C = model.sphere_center.copy()
        for j, jid in enumerate(ids):
            T = base_inv * data.oMi[jid]
            sel = model.sphere_joint == j
            C[sel] = model.sphere_center[sel] @ T.rotation.T + T.translation
        brute[i] = bool((np.linalg.norm(C[u] - C[v], axis=1) < r).any())
    assert 0.05 < brute.mean() < 0.5  # both verdicts occur
    np.testing.assert_array_equal(fast, brute)
