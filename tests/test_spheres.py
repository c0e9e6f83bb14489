"""The sphere self-collision model against the exact coal check (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.robots.collision import SelfCollision
from baseplace.robots.model import Robot
from baseplace.robots.spheres import SphereModel


@pytest.fixture(scope="module")
def tiago_spheres() -> SphereModel:
    """TIAGo's sphere model with its joint-pair tables (built once: it calibrates on 131 k samples)."""
    return SphereModel(Robot("tiago"))


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
    assert m.info.self_collision_checker.startswith("spheres-3: ")  # provenance of the drops
    save_map(m, tmp_path / "m.rmap")
    assert load_map(tmp_path / "m.rmap", robot).info == m.info  # the file keeps it


def _brute_force(robot: Robot, model: SphereModel, Q: np.ndarray, grow: float) -> np.ndarray:
    """Any of ``sphere_pairs`` overlapping with radii grown by ``grow`` (pair sum + grow).

    Sphere centres from pinocchio's joint placements, every pair tested: an oracle independent
    of the kernel's bounds and tables.
    """
    import pinocchio as pin

    arm = robot.arm()
    data = robot.model.createData()
    base = robot.model.getFrameId(arm.base_frame)
    ids = [robot.model.getJointId(j) for j in arm.joint_names]
    u, v = model.sphere_pairs[:, 0], model.sphere_pairs[:, 1]
    r = model.sphere_radius[u] + model.sphere_radius[v] + grow
    out = np.empty(len(Q), dtype=bool)
    for i, q in enumerate(Q):
        pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio(q, robot.q_reference))
        base_inv = data.oMf[base].inverse()
        C = model.sphere_center.copy()
        for j, jid in enumerate(ids):
            T = base_inv * data.oMi[jid]
            sel = model.sphere_joint == j
            C[sel] = model.sphere_center[sel] @ T.rotation.T + T.translation
        out[i] = bool((np.linalg.norm(C[u] - C[v], axis=1) < r).any())
    return out


def test_kernel_is_the_sphere_verdict_up_to_the_table_slack(tiago_spheres: SphereModel) -> None:
    """Bounds only skip work and joint-pair tables only err towards colliding, by their slack.

    Every configuration whose spheres overlap is called colliding, and every one called
    colliding has spheres within the largest table slack of each other.
    """
    model = tiago_spheres
    robot, arm = model.robot, model.arm
    assert len(model.table_joints) > 0 and 0 < model.table_delta.max() <= 0.004
    Q = arm.sample(np.random.default_rng(31), 400)
    fast = model.colliding_arm(arm, Q)
    exact = _brute_force(robot, model, Q, 0.0)
    grown = _brute_force(robot, model, Q, float(model.table_delta.max()))
    assert 0.05 < exact.mean() < 0.5  # both verdicts occur
    assert not np.any(exact & ~fast)  # never free where spheres overlap
    assert not np.any(fast & ~grown)  # colliding only within the slack


def test_configurations_beyond_the_tables_use_the_hierarchy(tiago_spheres: SphereModel) -> None:
    """Joint values outside the limits (no table covers them) get the exact sphere verdict."""
    model = tiago_spheres
    robot, arm = model.robot, model.arm
    push: set[int] = set()  # joints that put every table out of range, chosen greedily
    for J in model.table_joints:
        if not push & set(J[J >= 0].tolist()):
            push.add(int(J[J >= 0].max()))
    rng = np.random.default_rng(32)
    Q = arm.sample(rng, 300)
    for j in push:  # 0 to 0.05 past one of its limits
        past = 0.05 * rng.random(len(Q))
        Q[:, j] = np.where(rng.random(len(Q)) < 0.5, arm.lower[j] - past, arm.upper[j] + past)
    fast = model.colliding_arm(arm, Q)
    exact = _brute_force(robot, model, Q, 0.0)
    assert 0.05 < exact.mean() < 0.97  # both verdicts occur (limits often collide)
    np.testing.assert_array_equal(fast, exact)


def test_old_kernel_without_tables_is_exact_for_the_sphere_pairs() -> None:
    """Without joint-pair tables the verdict is that of every checked sphere pair."""
    robot = Robot("tiago")
    arm = robot.arm()
    model = SphereModel(robot, pair_tables=False)
    Q = arm.sample(np.random.default_rng(33), 300)
    np.testing.assert_array_equal(model.colliding_arm(arm, Q), _brute_force(robot, model, Q, 0.0))
