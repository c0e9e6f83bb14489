"""Joint-space edges checked by the robot's Cartesian motion; the pre-grasp derived from the hand."""

from __future__ import annotations

import itertools

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import PREGRASP_MARGIN, MotionChecker, MotionSettings
from baseplace.robots.collision import load_collision_model
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from baseplace.world.obstacles import Obstacle

TARGET = [0.75, -0.15, 0.85, 0.0, 0.0, 0.0]  # side grasp in front of the base, TCP x forward
TIP = "hand_middle_flex_3_link_0"  # TIAGo's foremost open fingertip


def _empty() -> VoxelMap:
    return VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64))


def _placements(robot, geom, arm, q_arm):
    """Oracle: pinocchio FK of every collision geometry, base frame = world (4, 4) each."""
    data, gdata = robot.model.createData(), pin.GeometryData(geom)
    q = arm.to_pinocchio(q_arm, robot.q_reference)
    pin.framesForwardKinematics(robot.model, data, q)
    pin.updateGeometryPlacements(robot.model, data, geom, gdata, q)
    T_root = data.oMf[robot.model.getFrameId(robot.spec.base_frame)].inverse().homogeneous
    return data, [T_root @ M.homogeneous for M in gdata.oMg], T_root


def _grasp_configuration(tiago):
    arm = tiago.arm()
    q = DampedLeastSquaresIK(arm).solve(pose_from_xyz_rpy(TARGET), np.random.default_rng(0))
    assert q is not None
    return arm, q


def test_a_fingertip_crossing_a_plate_between_coarse_states_is_refused(tiago):
    """The shoulder turns 0.048 rad (one state at 0.05 rad joint resolution): the foremost
    fingertip, ~1 m from its axis, sweeps ~5 cm sideways through a 1 cm plate standing where it is
    half way. Oracle: coal on the plate at 100 states along the line (the ends clear, the middle
    not). The straight line must be refused, and whatever path is returned must be clear."""
    from baseplace_experiments.table_grid import RobotShapes, TrueShape

    arm, q_mid = _grasp_configuration(tiago)
    j = list(arm.joint_names).index("arm_1_joint")
    step = np.zeros(arm.n_joints)
    step[j] = 0.024
    q_a, q_b = q_mid - step, q_mid + step
    geom = load_collision_model(tiago)
    k = [o.name for o in geom.geometryObjects].index(TIP)
    vertices = np.asarray(geom.geometryObjects[k].geometry.vertices())

    def tip(q):  # the fingertip vertex farthest along the TCP's x axis, in the base frame
        _, Ts, _ = _placements(tiago, geom, arm, q)
        p = vertices @ Ts[k][:3, :3].T + Ts[k][:3, 3]
        return p[np.argmax(p @ pose_from_xyz_rpy(TARGET)[:3, 0])]

    p, ahead = tip(q_mid), pose_from_xyz_rpy(TARGET)[:3, 0]
    t = tip(q_mid + step / 24) - p
    t /= np.linalg.norm(t)
    y = ahead - (ahead @ t) * t
    y /= np.linalg.norm(y)
    T_plate = np.eye(4)
    T_plate[:3, :3] = np.column_stack([t, y, np.cross(t, y)])
    T_plate[:3, 3] = p - 0.004 * y  # the tip 4 mm into the plate's 1 cm along the approach axis
    plate = coal.Box(0.01, 0.01, 0.02)
    shapes = RobotShapes(tiago)
    true = [TrueShape("plate", plate, T_plate)]
    line = [q_a + s * (q_b - q_a) for s in np.linspace(0.0, 1.0, 101)]
    touching = [shapes.touching(q, np.eye(4), true) for q in line]
    assert touching[0] is None and touching[-1] is None  # both ends clear of the plate
    assert any(c is not None and c.startswith("hand_middle_flex_3") for c in touching)  # crossed between

    obstacle = Obstacle("box#0", "box", plate, T_plate, "test plate", "plate")
    env = Environment(tiago, _empty(), shapes=[obstacle])
    motion = MotionChecker(
        tiago, arm, env, settings=MotionSettings(q_start=tuple(q_a), time_limit=5.0)
    )  # the default bound: no point of the robot moves more than 1 cm between checked states
    path, _ = motion.joint_path(q_b, np.eye(4), seed=0)
    assert path is None or len(path) > 2  # not the straight line
    if path is not None:
        for a, b in itertools.pairwise(path):
            n = max(1, int(np.ceil(np.abs(b - a).max() / 0.002)))
            for s in np.linspace(0.0, 1.0, n + 1):
                assert shapes.touching(a + s * (b - a), np.eye(4), true) is None


@pytest.mark.parametrize("radius", [0.035, 0.1505])
def test_derived_pregrasp_keeps_the_open_hand_clear_of_the_grasped_cylinder(tiago, radius):
    """A cylinder standing on the grasp point, as wide as a bottle, or as wide as anything held
    ahead of the TCP can be (its near face on the TCP's plane). At the approach's first state (the
    pre-grasp: pinocchio FK of what the checker returns) every collision geometry of the hand is at
    least the margin away from it (coal distance on the URDF's meshes)."""
    arm, q = _grasp_configuration(tiago)
    target = pose_from_xyz_rpy(TARGET)
    env = Environment(tiago, _empty())
    motion = MotionChecker(tiago, arm, env, settings=MotionSettings(pregrasp_distance=None))
    approach = motion.approach(q, target, np.eye(4))
    assert approach is not None
    geom = load_collision_model(tiago)
    last = tiago.model.getJointId(arm.joint_names[-1])
    hand = [k for k, o in enumerate(geom.geometryObjects) if last in set(tiago.model.supports[o.parentJoint])]
    assert len(hand) > 20  # the palm, the fingers and the wrist
    T_grasp = target @ tiago.T_tcp_grasp(arm.name)
    T_cyl = np.eye(4)
    T_cyl[:3, 3] = T_grasp[:3, 3]
    cylinder = coal.Cylinder(radius, 0.3)
    _, Ts, _ = _placements(tiago, geom, arm, approach[0])
    near = min(
        coal.distance(geom.geometryObjects[k].geometry, coal.Transform3s(Ts[k][:3, :3], Ts[k][:3, 3]), cylinder,
                      coal.Transform3s(T_cyl[:3, :3], T_cyl[:3, 3]), coal.DistanceRequest(), coal.DistanceResult())
        for k in hand
    )  # fmt: skip
    assert near >= PREGRASP_MARGIN - 1e-3
    assert motion.pregrasp_distance == pytest.approx(
        0.265, abs=0.001
    )  # TIAGo: 0.245 m fingertip reach + 0.02


def test_a_wide_grasped_object_gets_a_pregrasp_beyond_the_default_distance_clear_of_it(tiago):
    """A cylinder of 6 cm radius stands on the grasp point: at the default pre-grasp distance (0.15 m)
    TIAGo's open fingertips (0.245 m ahead of the TCP) are still 5.5 cm into it, so the transit (where
    nothing may touch it) cannot end there; the walk back goes on until the hand is clear of it (find-rate
    dev seed 25030: 72 of 100 candidates refused so). Oracle: pinocchio FK puts every approach state on
    the approach line, and coal on the true cylinder (the URDF's meshes, :class:`RobotShapes`) finds
    the whole robot clear of it at the pre-grasp and along the transit, and only the hand touching
    it along the approach."""
    from baseplace.placement.motion import transit_environment
    from baseplace.robots.fk import forward_kinematics
    from baseplace_experiments.table_grid import RobotShapes, TrueShape

    arm, q = _grasp_configuration(tiago)
    target = pose_from_xyz_rpy(TARGET)
    p_grasp = (target @ tiago.T_tcp_grasp(arm.name))[:3, 3]
    radius, height = 0.06, 0.3
    a, z = np.meshgrid(
        np.linspace(0, 2 * np.pi, 160, endpoint=False), np.linspace(-height / 2, height / 2, 61)
    )
    ring = np.c_[radius * np.cos(a.ravel()), radius * np.sin(a.ravel()), z.ravel()]
    r, b = np.meshgrid(np.linspace(0, radius, 13), np.linspace(0, 2 * np.pi, 160, endpoint=False))
    caps = [np.c_[r.ravel() * np.cos(b.ravel()), r.ravel() * np.sin(b.ravel()), np.full(r.size, s * height / 2)]
            for s in (-1, 1)]  # fmt: skip
    cells = VoxelMap.from_points(np.vstack([ring, *caps]) * 0.999 + p_grasp, resolution=0.005)
    approach_env = Environment(tiago, _empty(), grasped=cells)
    transit = transit_environment(tiago, {"obstacle": _empty()}, cells)
    assert transit is not None
    motion = MotionChecker(tiago, arm, transit, approach_environment=approach_env,
                           settings=MotionSettings(time_limit=5.0))  # fmt: skip
    assert motion.pregrasp_distance == pytest.approx(0.15)
    result = motion.check(q, np.eye(4), target)
    assert result is not None, motion.last_contacts

    T_cyl = np.eye(4)
    T_cyl[:3, 3] = p_grasp
    cylinder = TrueShape("cylinder", coal.Cylinder(radius, height), T_cyl)
    shapes = RobotShapes(tiago)
    axis = target[:3, :3] @ np.array([1.0, 0.0, 0.0])
    for state in result.approach:  # on the line, behind the grasp, the orientation kept
        T = forward_kinematics(arm, state)
        offset = T[:3, 3] - target[:3, 3]
        assert np.linalg.norm(offset - (offset @ axis) * axis) < 1e-3
        assert np.allclose(T[:3, :3], target[:3, :3], atol=1e-2)
        assert shapes.touching(state, np.eye(4), [], grasped=cylinder) is None  # only the hand may touch it
    back = -(forward_kinematics(arm, result.approach[0])[:3, 3] - target[:3, 3]) @ axis
    assert back > 0.15 + 1e-6  # beyond the default distance: there the fingertips were in the cylinder
    assert shapes.touching(result.approach[0], np.eye(4), [cylinder]) is None  # pre-grasp: all clear
    for p, n in itertools.pairwise(result.path):
        for s in np.linspace(0.0, 1.0, max(2, int(np.ceil(np.abs(n - p).max() / 0.01)) + 1)):
            assert shapes.touching(p + s * (n - p), np.eye(4), [cylinder]) is None
