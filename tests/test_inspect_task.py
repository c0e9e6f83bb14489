"""Seed 002's inspect task with a PDDL planner: the geometric grounding against pinocchio, the plans."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import shapely

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose
from baseplace.placement.surface_map import build_surface_map
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.terrain.polygons import footprint_in_world, footprint_outline
from baseplace_experiments.inspect_task import (
    INSPECT_TABLE,
    ReachCheck,
    TaskSettings,
    place_objects,
    predefined_poses,
    run_inspect_experiment,
    run_inspect_task,
)


@pytest.fixture(scope="module")
def pr2_maps(pr2):
    return {arm: build_map(pr2, arm, BuildSettings(samples=2_000_000, seed=7)) for arm in ("left", "right")}


@pytest.fixture(scope="module")
def table(pr2, pr2_maps):
    return build_surface_map(pr2, pr2_maps, *INSPECT_TABLE, resolution=0.05, orientations=16, combine="any")


def _tcp_in_world(robot, arm, q, pose: BasePose) -> np.ndarray:
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
    T_base_tcp = (
        data.oMf[model.getFrameId(arm.base_frame)].inverse() * data.oMf[model.getFrameId(arm.tcp_frame)]
    )
    return pose.matrix() @ T_base_tcp.homogeneous


def test_predefined_poses_face_the_table_from_outside(pr2, table):
    poses = predefined_poses(pr2, table, gap=0.05)
    assert len(poses) == 4
    poly = shapely.Polygon(table.polygon)
    outline = footprint_outline(pr2.spec.footprint_radius, pr2.spec.footprint_polygon)
    for pose in poses:
        foot = shapely.Polygon(footprint_in_world(outline, pose.matrix()))
        assert not foot.intersects(poly) and abs(foot.distance(poly) - 0.05) < 1e-9
        to_centre = np.array(poly.centroid.coords[0]) - (pose.x, pose.y)
        assert abs(math.remainder(math.atan2(to_centre[1], to_centre[0]) - pose.yaw, 2 * math.pi)) < 1e-9
    assert [round(p.y, 3) for p in poses[:2]] == sorted(round(p.y, 3) for p in poses[:2])  # long sides first
    assert all(abs(p.x - 0.7) < 1e-9 for p in poses[:2])


def test_reach_check_grasps_verified_by_pinocchio(pr2, pr2_maps, table):
    s = TaskSettings()
    check = ReachCheck(pr2, pr2_maps, table, s)
    p_o = np.array([0.7, 0.2, 0.74 + 0.5 * s.object_height])
    near = predefined_poses(pr2, table)[0]  # the long side at y < 0, 0.72 m from the object
    rng = np.random.default_rng(0)
    placement = check(near, p_o, rng)
    assert placement is not None
    arm = next(pr2.arm(a) for a in pr2_maps if pr2.arm(a).joint_names == placement.joint_names)
    T = _tcp_in_world(pr2, arm, placement.joints[0], near)
    G = check.grasps(p_o)
    errs = [
        np.linalg.norm(T[:3, 3] - g[:3, 3]) + np.linalg.norm(pin.log3(g[:3, :3].T @ T[:3, :3])) for g in G
    ]
    assert min(errs) < 2e-3
    assert T[2, 0] < -0.99  # the approach axis points down: a top-down grasp
    assert check(BasePose(-2.0, -2.0, 0.0), p_o, rng) is None  # 2.5 m away


def test_far_corner_object_unsolved_with_one_pose_solved_by_sampling(pr2, pr2_maps, table):
    s = TaskSettings()
    corner = np.array([[1.33, 0.58, 0.74 + 0.5 * s.object_height]])  # the far corner of the table
    start = BasePose(-1.5, -1.5, math.pi / 4)
    one = run_inspect_task(pr2, pr2_maps, table, corner, start, "predefined", np.random.default_rng(0), s, 1)
    assert not one.solved and one.unreachable == 1
    assert one.actions == [
        "move(start, p1)",
        "inspect_surface(p1)",
    ]  # the table is seen, the object not reached

    sampled = run_inspect_task(pr2, pr2_maps, table, corner, start, "sampled", np.random.default_rng(0), s)
    assert sampled.solved and sampled.unreachable == 0
    assert sampled.replans >= 2  # first no pose at all, then the object appears
    names = [a.split("(")[0] for a in sampled.actions]
    assert names[:2] == ["move", "inspect_surface"]
    assert names[-3:] == ["pickup", "inspect_object", "putdown"]
    assert sampled.moves == names.count("move") and sampled.other_actions == len(names) - sampled.moves
    # the modelled time is the sum of the executed actions
    assert sampled.exec_s >= s.inspect_surface_s + s.pickup_s + s.inspect_object_s + s.putdown_s


def test_experiment_rows_and_bad_input(pr2, pr2_maps, table):
    result = run_inspect_experiment(pr2, pr2_maps, table, counts=(2,), runs=1, seed=3)
    configs = [r["config"] for r in result["summary"]]
    assert configs == ["1 pose", "2 poses", "3 poses", "4 poses", "sampling"]
    assert all(r["runs"] == 1 for r in result["summary"])
    sampling = result["summary"][-1]
    assert sampling["unsolved"] == 0
    for row in result["runs"]:
        if row["solved"]:
            done = [a for a in row["actions"] if a.startswith("inspect_object")]
            assert sorted(done) == ["inspect_object(o0)", "inspect_object(o1)"]
    with pytest.raises(InputError, match="runs"):
        run_inspect_experiment(pr2, pr2_maps, table, counts=(1,), runs=0)
    with pytest.raises(InputError, match="mode"):
        run_inspect_task(pr2, pr2_maps, table, np.zeros((1, 3)), BasePose(0, 0, 0), "teleport",
                         np.random.default_rng(0))  # fmt: skip
    with pytest.raises(InputError, match="cannot place"):
        place_objects(table, 40, np.random.default_rng(0), TaskSettings(object_spacing=0.5))
