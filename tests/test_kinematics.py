from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.robots.spec import BUILTIN_ROBOTS, builtin_spec
from conftest import DATA

ARMS = [(name, arm) for name in BUILTIN_ROBOTS for arm in builtin_spec(name).arms] + [("planar3", "arm")]


def _robot(name: str) -> Robot:
    return Robot(DATA / "planar3.toml") if name == "planar3" else Robot(name)


def pinocchio_fk(robot: Robot, arm, Q):
    """Independent oracle: pinocchio's own frame placements, base frame to TCP frame."""
    model, data = robot.model, robot.model.createData()
    base, tcp = model.getFrameId(arm.base_frame), model.getFrameId(arm.tcp_frame)
    out = np.empty((len(Q), 4, 4))
    for i, q in enumerate(Q):
        pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
        out[i] = (data.oMf[base].inverse() * data.oMf[tcp]).homogeneous
    return out


@pytest.mark.parametrize(("robot_name", "arm_name"), ARMS)
def test_fk_agrees_with_pinocchio(robot_name, arm_name):
    robot = _robot(robot_name)
    arm = robot.arm(arm_name)
    Q = arm.sample(np.random.default_rng(0), 10_000)
    expected = pinocchio_fk(robot, arm, Q)
    assert np.abs(forward_kinematics(arm, Q) - expected).max() < 1e-9
    generated = np.empty((len(Q), 4, 4))
    arm_kernels(arm).fk_batch(Q, generated)
    assert np.abs(generated - expected).max() < 1e-9
    np.testing.assert_allclose(forward_kinematics(arm, Q[0]), expected[0], atol=1e-9)


def test_arm_joints_are_sorted_along_the_chain(planar3):
    arm = planar3.arm()
    assert arm.joint_names == ("lift", "joint1", "joint2", "joint3")
    # joint_limits override from the TOML file
    assert tuple(arm.lower[1:2]) == (-2.0,) and tuple(arm.upper[1:2]) == (2.0,)


def test_pr2_continuous_joints_wrap(pr2):
    arm = pr2.arm("left")
    assert arm.continuous.sum() == 2
    assert np.all(arm.lower[arm.continuous] == -np.pi)
    q = arm.sample(np.random.default_rng(1), 1)[0]
    np.testing.assert_allclose(arm.from_pinocchio(arm.to_pinocchio(q, pr2.q_reference)), q, atol=1e-12)


@pytest.mark.parametrize(("robot_name", "arm_name"), [("tiago", "arm"), ("pr2", "right"), ("planar3", "arm")])
def test_ik_reaches_fk_targets(robot_name, arm_name):
    robot = _robot(robot_name)
    arm = robot.arm(arm_name)
    rng = np.random.default_rng(11)
    n = 1000 if robot_name == "tiago" else 200
    Q = arm.sample(rng, n)
    targets = pinocchio_fk(robot, arm, Q)
    if robot_name == "planar3":  # 4 joints cannot reach arbitrary 6D poses: check the samples
        targets = targets[:50]
    ik = DampedLeastSquaresIK(arm)
    q, ok = ik.solve_batch(targets, rng)
    assert ok.mean() >= (0.995 if robot_name != "planar3" else 0.9)
    reached = pinocchio_fk(robot, arm, q[ok])  # checked by pinocchio, not by our own FK
    assert np.abs(reached[:, :3, 3] - targets[ok][:, :3, 3]).max() < 2e-4
    rot_err = np.einsum("nij,nij->n", reached[:, :3, :3], targets[ok][:, :3, :3])  # trace(R1^T R2)
    assert np.all(np.arccos(np.clip((rot_err - 1) / 2, -1, 1)) < 2e-3)
    assert np.all(arm.within_limits(q[ok]))


def test_the_damped_step_is_lapacks_solution():
    """The IK's damped least-squares step, solved by its own 6 x 6 Cholesky factorisation, against
    numpy's (LAPACK's) solve of the same system: Jacobians of 6-8 columns, full rank, with a zeroed
    column (a joint held at its limit) and of rank 3, damping from 1e-4 (the solver's) to 1."""
    from baseplace.robots.ik import _damped_solve

    rng = np.random.default_rng(4)
    A, y = np.empty((6, 6)), np.empty(6)
    for case in range(60):
        n = 6 + case % 3
        J = rng.normal(size=(6, n))
        if case % 4 == 1:
            J[:, rng.integers(n)] = 0.0
        elif case % 4 == 2:
            J = rng.normal(size=(6, 3)) @ rng.normal(size=(3, n))
        e, lam = rng.normal(size=6), float(10.0 ** rng.uniform(-4, 0))
        dq = np.empty(n)
        _damped_solve(J, e, lam, A, y, dq)
        expected = J.T @ np.linalg.solve(J @ J.T + lam * np.eye(6), e)
        np.testing.assert_allclose(dq, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())


def test_ik_from_another_start_and_world_frame(tiago, rng):
    arm = tiago.arm()
    q_true = arm.sample(rng, 1)[0]
    T_base_tcp = forward_kinematics(arm, q_true)
    T_world_base = np.eye(4)
    T_world_base[:3, 3] = [2.0, -1.0, 0.0]
    ik = DampedLeastSquaresIK(arm)
    q = ik.solve_world(T_world_base @ T_base_tcp, T_world_base, rng, q_seed=arm.sample(rng, 1)[0])
    assert q is not None
    reached = pinocchio_fk(tiago, arm, q[None])[0]
    np.testing.assert_allclose(reached[:3, 3], T_base_tcp[:3, 3], atol=1e-4)
    cos_angle = (np.trace(reached[:3, :3].T @ T_base_tcp[:3, :3]) - 1) / 2
    assert np.arccos(min(1.0, cos_angle)) < 1e-3


def test_ik_unreachable_target_returns_none(tiago, rng):
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 1.0]  # far beyond reach
    assert DampedLeastSquaresIK(tiago.arm(), restarts=5).solve(T, rng) is None
    T[0, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        DampedLeastSquaresIK(tiago.arm()).solve(T, rng)
