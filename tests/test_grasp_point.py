"""``--grasp-point``: a target given where the fingertips close, not where the TCP frame sits (issue 29 item 4)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import matrix_to_rpy, parse_pose6
from baseplace.jobs.inputs import CloudInput
from baseplace.jobs.place import PlaceJob, place_job
from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings
from baseplace.sim.scenes import SceneSettings, generate_scene
from conftest import DATA, run_cli


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(5)
    generated = generate_scene(SceneSettings(n_planes=2, extent=(6.0, 6.0)), rng)
    plane = generated.planes[1]
    cx, cy = plane.center
    z = float(plane.z(np.array([[cx, cy]]))[0]) + 0.75
    return generated.sample_cloud(rng), f"{cx} {cy} {z} 0 1.5708 0.3"


def _pose_text(T: np.ndarray) -> str:
    return " ".join(repr(float(v)) for v in (*T[:3, 3], *matrix_to_rpy(T[:3, :3])))


def _place(tiago, tiago_map, points, **given):
    # stand_on "any": the target lies over plane 1 of a generated scene, a raised platform or a ramp
    job = PlaceJob(robot=tiago, map=tiago_map, cloud=CloudInput(points=points), seed=4,
                   settings=PlaceSettings(placements=2, tries=200, stand_on="any", **POSE_ONLY_CHECKS),
                   segmentation_cache=False, **given)  # fmt: skip
    return place_job(job)


def _grasp_frame_in_world(robot, row: dict, arm_joints: dict[str, float]) -> np.ndarray:
    """Pinocchio FK, independent of baseplace's kernels: the URDF's grasp frame for the placement's joints."""
    model = robot.model
    q = robot.q_reference.copy()
    for name, value in arm_joints.items():
        joint = model.joints[model.getJointId(name)]
        if joint.nq == 2:  # continuous: pinocchio stores cos, sin
            q[joint.idx_q : joint.idx_q + 2] = (np.cos(value), np.sin(value))
        else:
            q[joint.idx_q] = value
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    T_base_grasp = (data.oMf[model.getFrameId("base_footprint")].inverse() * data.oMf[model.getFrameId("hand_grasping_frame")]).homogeneous  # fmt: skip
    return np.asarray(row["base_pose"]) @ T_base_grasp


def test_grasp_point_equals_the_tcp_target_moved_back_and_fk_puts_the_grasp_frame_there(
    scene, tiago, tiago_map
):
    points, grasp_text = scene
    G = parse_pose6(grasp_text)
    # the TCP behind the grasp point: arm_tool_link is 0.151 m back along the approach axis (x)
    # and 2 cm aside, as the URDF places hand_grasping_frame (read here with pinocchio, not the spec)
    T_tcp_grasp = tiago.frame_pose(tiago.q_reference, "hand_grasping_frame", relative_to="arm_tool_link")
    assert T_tcp_grasp[0, 3] == pytest.approx(0.1506, abs=1e-3)
    T = G @ np.linalg.inv(T_tcp_grasp)

    by_grasp = _place(tiago, tiago_map, points, targets=[], grasp_points=[grasp_text])
    by_tcp = _place(tiago, tiago_map, points, targets=[_pose_text(T)])
    assert by_grasp.placements, by_grasp.failures
    assert len(by_grasp.placements) == len(by_tcp.placements)
    for a, b in zip(by_grasp.placements, by_tcp.placements, strict=True):
        np.testing.assert_allclose(a["base_pose"], b["base_pose"], atol=1e-5)
        assert a["joints"][0] == pytest.approx(b["joints"][0], abs=1e-5)
    np.testing.assert_allclose(parse_pose6(by_grasp.targets[0]), T, atol=2e-4)  # the TCP target it solved for
    assert by_grasp.inputs["grasp_points"] == [grasp_text]

    for row in by_grasp.placements:
        T_world_grasp = _grasp_frame_in_world(tiago, row, row["joints"][0])
        assert np.linalg.norm(T_world_grasp[:3, 3] - G[:3, 3]) < 0.01
        assert np.linalg.norm(T_world_grasp[:3, 0] - G[:3, 0]) < 0.05  # the same approach direction


def test_target_and_grasp_point_together_are_refused():
    with pytest.raises(InputError, match="not both"):
        place_job(
            PlaceJob(
                ["1 0 0.8 0 0 0"], grasp_points=["1 0 0.8 0 0 0"], cloud=CloudInput(points=np.zeros((3, 3)))
            )
        )
    r = run_cli(
        "place", "--cloud", "scene.ply", "--target", "1 0 0.8 0 0 0", "--grasp-point", "1 0 0.8 0 0 0"
    )
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "error: give --target (the TCP pose) or --grasp-point (the point between the fingertips), not both"
    ]


def test_a_grasp_point_in_degrees_is_refused_with_the_option_named_and_read_with_degrees(tmp_path):
    r = run_cli("place", "--cloud", str(tmp_path / "none.ply"), "--grasp-point", "1 0 0.8 0 90 0")
    assert r.returncode == 2 and "--grasp-point" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = run_cli(
        "place", "--cloud", str(tmp_path / "none.ply"), "--grasp-point", "1 0 0.8 0 90 0", "--degrees"
    )
    assert r.returncode == 2 and "--grasp-point" not in r.stderr and "none.ply" in r.stderr


def test_a_robot_file_names_its_grasp_frame_and_a_moving_one_is_refused(tmp_path):
    import shutil

    from baseplace.placement.irm_candidates import grasp_standoff
    from baseplace.robots.model import Robot

    assert np.allclose(Robot("pr2").T_tcp_grasp(), np.eye(4))  # its TCP is between the fingertips
    shutil.copy(DATA / "planar3.urdf", tmp_path)
    spec = (DATA / "planar3.toml").read_text()

    def robot(grasp_frame: str) -> Robot:
        text = spec.replace('tcp_frame = "tool0"', f'tcp_frame = "tool0"\ngrasp_frame = "{grasp_frame}"')
        (tmp_path / "r.toml").write_text(text)
        return Robot(tmp_path / "r.toml")

    assert np.allclose(robot("tool0").T_tcp_grasp(), np.eye(4))
    assert grasp_standoff(robot("tool0")) == 0.0 and grasp_standoff(Robot("pr2")) == 0.0
    tiago = Robot(
        "tiago"
    )  # candidates' standoff and the auto object's grasp point: the URDF's, no robot names
    assert grasp_standoff(tiago) == pytest.approx(
        tiago.frame_pose(tiago.q_reference, "hand_grasping_frame", "arm_tool_link")[0, 3], abs=1e-4
    )
    with pytest.raises(InputError, match="must be fixed to the link of TCP frame 'tool0'"):
        robot("link1").T_tcp_grasp()
    with pytest.raises(InputError, match="grasp frame"):
        robot("no_such_frame").T_tcp_grasp()


def test_explain_with_a_grasp_point_checks_the_tcp_target_behind_it(tiago, tiago_map):
    from baseplace.jobs.explain import ExplainJob, explain_job

    grasp_text = "0.95 -0.2 0.8 0 0 0.4"
    T = parse_pose6(grasp_text) @ np.linalg.inv(
        tiago.frame_pose(tiago.q_reference, "hand_grasping_frame", "arm_tool_link")
    )
    by_grasp = explain_job(ExplainJob("0.2 -0.1 0", None, tiago_map, tiago, grasp_point=grasp_text)).to_json()
    by_tcp = explain_job(ExplainJob("0.2 -0.1 0", _pose_text(T), tiago_map, tiago)).to_json()
    assert by_grasp["ik"]["solved"], by_grasp["verdict"]
    assert by_grasp["ik"]["joints"] == pytest.approx(by_tcp["ik"]["joints"], abs=1e-6)
    assert by_grasp["verdict"] == by_tcp["verdict"] and by_grasp["map"] == by_tcp["map"]
    row = {"base_pose": by_grasp["base"]["base_pose"]}
    assert (
        np.linalg.norm(_grasp_frame_in_world(tiago, row, by_grasp["ik"]["joints"])[:3, 3] - [0.95, -0.2, 0.8])
        < 0.01
    )
    r = run_cli("explain", "--base", "0 0 0", "--target", grasp_text, "--grasp-point", grasp_text)
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "error: give --target (the TCP pose) or --grasp-point (the point between the fingertips), not both"
    ]


def test_the_grasp_offset_and_the_stowed_joints_are_read_once_per_arm_and_kept_read_only(tiago):
    """The grasp frame's offset is read from the URDF once per arm (not per query): the same array
    each time, read only, so that no caller can change it for the next query; pinocchio FK of the
    two frames is the oracle. The arm carries its spec's stowed joint values."""
    from baseplace.placement.motion import stowed_configuration

    T = tiago.T_tcp_grasp()
    assert T is tiago.T_tcp_grasp(tiago.spec.default_arm) and not T.flags.writeable
    with pytest.raises(ValueError):
        T[0, 3] = 1.0
    spec = tiago.spec.arm()
    assert np.allclose(T, tiago.frame_pose(tiago.q_reference, spec.grasp_frame, relative_to=spec.tcp_frame))
    arm = tiago.arm()
    assert arm.stowed is not None and np.array_equal(arm.stowed, spec.stowed)
    assert np.array_equal(stowed_configuration(tiago, arm), spec.stowed)
