"""Robot files for arms on mobile bases: mount, approach axis, package folders, ``robot check``.

Oracles: pinocchio on the unchanged example-robot-data URDFs (FK of the mounted arm), the known
approach axes of the UR and Panda TCP frames (z) and of TIAGo and PR2 (x), and geometry written
by hand (obstacle voxels placed against the base body).
"""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.jobs.text import report_text
from baseplace.robots.check import check_robot
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.model import Robot
from baseplace.robots.spec import example_robot_data_dir, load_spec
from conftest import run_cli as run

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
ERD = example_robot_data_dir() / "example-robot-data" / "robots"
UR5_URDF = ERD / "ur_description" / "urdf" / "ur5_robot.urdf"
PANDA_URDF = ERD / "panda_description" / "urdf" / "panda.urdf"
KINOVA_URDF = ERD / "kinova_description" / "robots" / "kinova.urdf"
KINOVA_SRDF = ERD / "kinova_description" / "srdf" / "kinova.srdf"  # disables no pair
# the SRDF's "arm_up" pose, joint 3 at +pi/2 (its -pi/2 lies outside [0.33, 5.95])
KINOVA_REFERENCE = {"j2s6s200_joint_1": 1.5707, "j2s6s200_joint_2": 2.618, "j2s6s200_joint_3": 1.5707,
                    "j2s6s200_joint_4": 3.1415, "j2s6s200_joint_5": 2.618, "j2s6s200_joint_6": 0.0}  # fmt: skip


def _kinova_file(folder: Path, srdf: Path = KINOVA_SRDF, name: str = "kinova_base") -> Path:
    """example-robot-data's Kinova Jaco (continuous joints 1, 4 and 6) on a mobile base."""
    path = folder / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\n'
        'urdf = "package://example-robot-data/robots/kinova_description/robots/kinova.urdf"\n'
        f"srdf = {json.dumps(str(srdf))}\n"
        'base_frame = "base_footprint"\nfootprint = { radius = 0.3 }\n'
        "[mount]\nxyz = [0.0, 0.0, 0.4]\nrpy = [0.0, 0.0, 0.0]\n"
        f"[arms.arm]\njoints = {json.dumps(list(KINOVA_REFERENCE))}\n"
        'tcp_frame = "j2s6s200_end_effector"\napproach = "x"\n'
        "[reference]\n" + "".join(f"{j} = {v}\n" for j, v in KINOVA_REFERENCE.items())
    )
    return path


def _pinocchio_q(model: pin.Model, joints: dict[str, float]) -> np.ndarray:
    """pinocchio's configuration for joint angles: (cos, sin) in the two slots of a continuous joint."""
    q = pin.neutral(model)
    for name, value in joints.items():
        joint = model.joints[model.getJointId(name)]
        q[joint.idx_q : joint.idx_q + joint.nq] = (
            [math.cos(value), math.sin(value)] if joint.nq == 2 else [value]
        )
    return q


def _pinocchio_mounted_fk(urdf: Path, root: str, xyz, rpy, tcp: str, joint_names, Q) -> np.ndarray:
    """T_base_tcp from pinocchio on the full, unmounted URDF, times the mount pose."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    T_base_root = pin.SE3(pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float)), np.asarray(xyz, dtype=float))
    out = np.empty((len(Q), 4, 4))
    for k, q_arm in enumerate(Q):
        q = pin.neutral(model)
        for name, value in zip(joint_names, q_arm, strict=True):
            q[model.joints[model.getJointId(name)].idx_q] = value
        pin.framesForwardKinematics(model, data, q)
        T_root_tcp = data.oMf[model.getFrameId(root)].inverse() * data.oMf[model.getFrameId(tcp)]
        out[k] = (T_base_root * T_root_tcp).homogeneous
    return out


@pytest.mark.parametrize(
    ("robot_file", "urdf", "root", "tcp"),
    [
        ("ur5_base.toml", UR5_URDF, "base_link", "tool0"),
        ("panda_base.toml", PANDA_URDF, "panda_link0", "panda_hand_tcp"),
    ],
)
def test_example_robots_load_and_fk_of_the_mounted_arm_matches_pinocchio(robot_file, urdf, root, tcp):
    robot = Robot(EXAMPLES / robot_file)
    mount = robot.spec.mount
    assert mount is not None and robot.spec.base_frame == "base_footprint"
    arm = robot.arm()
    assert arm.tcp_frame == tcp and arm.approach_axis.tolist() == [0.0, 0.0, 1.0]
    Q = arm.sample(np.random.default_rng(7), 500)
    expected = _pinocchio_mounted_fk(urdf, root, mount.xyz, mount.rpy, tcp, arm.joint_names, Q)
    assert np.abs(forward_kinematics(arm, Q) - expected).max() < 1e-9
    generated = np.empty((len(Q), 4, 4))
    arm_kernels(arm).fk_batch(Q, generated)
    assert np.abs(generated - expected).max() < 1e-9


def test_a_rotated_mount_moves_the_whole_arm(tmp_path):
    text = (EXAMPLES / "ur5_base.toml").read_text().replace("rpy = [0.0, 0.0, 0.0]", "rpy = [0.1, -0.2, 2.5]")
    (tmp_path / "ur5_tilted.toml").write_text(text.replace('name = "ur5_base"', 'name = "ur5_tilted"'))
    robot = Robot(tmp_path / "ur5_tilted.toml")
    arm = robot.arm()
    Q = arm.sample(np.random.default_rng(1), 200)
    expected = _pinocchio_mounted_fk(
        UR5_URDF, "base_link", (0, 0, 0.4), (0.1, -0.2, 2.5), "tool0", arm.joint_names, Q
    )
    assert np.abs(forward_kinematics(arm, Q) - expected).max() < 1e-9
    assert (
        robot.spec.urdf_sha256 != Robot(EXAMPLES / "ur5_base.toml").spec.urdf_sha256
    )  # maps tell them apart


def test_mounted_base_body_collides_with_an_obstacle_beside_it():
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment

    robot = Robot(EXAMPLES / "ur5_base.toml")  # base: a 0.3 m disc from 0.05 to 0.4 m
    T = np.eye(4)

    def collides(point) -> bool:
        voxels = VoxelMap.from_points(np.array([point], dtype=float), 0.02)
        return Environment(robot, voxels).colliding(robot.q_reference, T)

    assert collides([0.0, -0.25, 0.2])  # inside the disc, below the arm
    assert not collides([0.0, -0.40, 0.2])  # beside it
    assert not collides([0.0, -0.25, 0.8])  # above the base, clear of the stretched-out arm


@pytest.mark.parametrize(
    ("robot_file", "urdf_name"), [("ur5_base.toml", "ur5"), ("panda_base.toml", "panda")]
)
def test_robot_check_flags_an_approach_axis_that_does_not_point_out_of_the_hand(
    tmp_path, robot_file, urdf_name
):
    good = run("robot", "check", str(EXAMPLES / robot_file), "--png", str(tmp_path / "good.png"), "--json")
    assert good.returncode == 0, good.stderr
    report = json.loads(good.stdout)
    assert not [w for w in report["warnings"] if "approach" in w], report["warnings"]
    assert (tmp_path / "good.png").stat().st_size > 20_000
    assert report["arms"]["arm"]["approach"] == "z" and report["collision"]["pairs"] > 0
    # the same file, approach left at the default x: a UR tool0 and a Panda hand TCP approach along z
    wrong = tmp_path / f"{urdf_name}_x.toml"
    wrong.write_text((EXAMPLES / robot_file).read_text().replace('approach = "z"', ""))
    proc = run("robot", "check", str(wrong), "--png", str(tmp_path / "wrong.png"))
    assert proc.returncode == 0, proc.stderr
    flagged = [
        line for line in proc.stdout.splitlines() if line.startswith("warning:") and "approach" in line
    ]
    assert len(flagged) == 1 and "approach axis x" in flagged[0] and 'set approach = "z"' in flagged[0]
    # pointing backwards, into the hand
    backwards = tmp_path / f"{urdf_name}_minus_z.toml"
    backwards.write_text((EXAMPLES / robot_file).read_text().replace('approach = "z"', 'approach = "-z"'))
    report = check_robot(Robot(backwards))
    assert any("points back into the hand" in w for w in report.warnings)


@pytest.mark.parametrize("name", ["tiago", "pr2"])
def test_builtin_robots_approach_axes_pass_the_check(name):
    report = check_robot(Robot(name))
    assert not [w for w in report.warnings if "approach" in w]


def test_robot_check_flags_a_footprint_smaller_than_the_base():
    """TIAGo's PMB2 base is a 0.54 m disc: a 0.2 m footprint radius leaves its meshes outside."""
    import dataclasses

    tiago = load_spec("tiago")
    report = check_robot(Robot(dataclasses.replace(tiago, footprint_radius=0.2)))
    assert any("footprint is smaller than the base" in w for w in report.warnings)
    assert not any("footprint" in w for w in check_robot(Robot(tiago)).warnings)


def test_robot_check_flags_a_reference_configuration_outside_the_joint_limits(tmp_path):
    """Panda's joint 4 lies in [-3.07, -0.07] rad: the all-zero configuration is outside."""
    text = (EXAMPLES / "panda_base.toml").read_text()
    assert not [w for w in check_robot(Robot(EXAMPLES / "panda_base.toml")).warnings if "reference" in w]
    (tmp_path / "panda.toml").write_text(text.replace("panda_joint4 = -2.356194\n", ""))
    flagged = [
        w for w in check_robot(Robot(tmp_path / "panda.toml")).warnings if "outside the joint limits" in w
    ]
    assert len(flagged) == 1 and "panda_joint4 = 0 not in [-3.07, -0.0698]" in flagged[0]


def test_robot_check_flags_an_arm_link_without_collision_geometry(tmp_path):
    """The UR5 URDF copied with the forearm's collision element removed (its meshes still found)."""
    text = UR5_URDF.read_text()
    start = text.index('<link name="forearm_link">')
    c0 = text.index("<collision>", start)
    c1 = text.index("</collision>", c0) + len("</collision>")
    (tmp_path / "ur5.urdf").write_text(text[:c0] + text[c1:])
    robot_file = (
        (EXAMPLES / "ur5_base.toml")
        .read_text()
        .replace(
            'urdf = "package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"',
            'urdf = "ur5.urdf"',
        )
    )
    (tmp_path / "ur5.toml").write_text(robot_file)
    report = check_robot(Robot(tmp_path / "ur5.toml"))
    flagged = [w for w in report.warnings if "no collision geometry" in w]
    assert len(flagged) == 1 and flagged[0].endswith(": forearm_link")
    assert not [
        w for w in check_robot(Robot(EXAMPLES / "ur5_base.toml")).warnings if "collision geometry" in w
    ]


def _write_package(tmp_path: Path) -> Path:
    """A ROS-style package folder: ws/my_arm/{urdf/arm.urdf, meshes/link.stl} with package:// URIs."""
    pkg = tmp_path / "ws" / "my_arm"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    shutil.copy(
        ERD / "ur_description" / "meshes" / "ur5" / "collision" / "base.stl", pkg / "meshes" / "link.stl"
    )
    (pkg / "urdf" / "arm.urdf").write_text(
        '<robot name="my_arm"><link name="root"><collision><geometry>'
        '<mesh filename="package://my_arm/meshes/link.stl"/></geometry></collision></link>'
        '<joint name="j1" type="revolute"><parent link="root"/><child link="l1"/><axis xyz="0 0 1"/>'
        '<origin xyz="0 0 0.1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<link name="l1"><collision><geometry><box size="0.05 0.05 0.3"/></geometry>'
        '<origin xyz="0 0 0.15"/></collision></link>'
        '<joint name="tcp_joint" type="fixed"><parent link="l1"/><child link="tcp"/><origin xyz="0 0 0.3"/></joint>'
        '<link name="tcp"/></robot>'
    )  # fmt: skip
    (tmp_path / "my_arm.toml").write_text(
        'name = "my_arm"\nurdf = "ws/my_arm/urdf/arm.urdf"\nbase_frame = "base_footprint"\n'
        "footprint = { radius = 0.3 }\n[mount]\nxyz = [0, 0, 0.5]\n"
        '[arms.arm]\njoints = ["j1"]\ntcp_frame = "tcp"\napproach = "z"\n'
    )  # fmt: skip
    return tmp_path / "my_arm.toml"


def test_package_folders_are_found_and_a_missing_mesh_fails_at_load(tmp_path):
    robot_file = _write_package(tmp_path)
    robot = Robot(robot_file)  # no package_dirs: my_arm is an ancestor of the URDF
    mesh = (tmp_path / "ws" / "my_arm" / "meshes" / "link.stl").resolve()
    assert str(mesh) in robot.urdf.xml and "package://" not in robot.urdf.xml
    (tmp_path / "ws" / "my_arm" / "meshes" / "link.stl").unlink()
    with pytest.raises(
        InputError, match=r"collision mesh 'package://my_arm/meshes/link.stl' of link 'root' not found"
    ):
        Robot(robot_file)
    proc = run("robot", "check", str(robot_file), "--png", str(tmp_path / "x.png"))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "package_dirs" in proc.stderr and not (tmp_path / "x.png").exists()


def test_a_removed_world_link_gets_urdfdoms_explanation(tmp_path):
    text = (ERD / "ur_description" / "urdf" / "ur10_robot.urdf").read_text()
    assert '<link name="world"/>' in text
    urdf = tmp_path / "ur10.urdf"
    urdf.write_text(text.replace('<link name="world"/>', ""))
    (tmp_path / "ur10.toml").write_text(
        'name = "ur10"\nurdf = "ur10.urdf"\nbase_frame = "base_link"\nfootprint = { radius = 0.3 }\n'
        '[arms.arm]\njoints = ["shoulder_pan_joint"]\ntcp_frame = "tool0"\n'
    )  # fmt: skip
    with pytest.raises(InputError) as err:
        Robot(tmp_path / "ur10.toml")
    message = str(err.value)
    assert "parent link [world] of joint [world_joint] not found" in message and "\n" not in message
    assert "remove this joint [world_joint]" in message


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (('approach = "z"', 'approach = "w"'), "unknown TCP approach axis 'w'"),
        (("xyz = [0.0, 0.0, 0.4]", "xyz = [0.0, 0.0]"), "mount needs xyz"),
        (("[mount]", "[mount]\nheight = 1"), "mount must be a table with keys"),
        (('base_frame = "base_footprint"', 'base_frame = "base_link"'), "already a link"),
    ],
)
def test_bad_mount_and_approach_are_one_line_errors(tmp_path, edit, fragment):
    path = tmp_path / "bad.toml"
    path.write_text((EXAMPLES / "ur5_base.toml").read_text().replace(*edit))
    with pytest.raises(InputError, match=fragment):
        Robot(path)


def test_side_and_top_grasps_follow_the_approach_axis():
    from baseplace.placement.irm_candidates import grasp_poses

    p_o = np.array([1.0, 2.0, 0.7])
    for axis in ([1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0], [-1.0, 0, 0]):
        a = np.asarray(axis)
        T = grasp_poses(p_o, n=8, top_down=True, standoff=0.1, approach_axis=a)
        assert np.allclose(T[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2), np.eye(3), atol=1e-12)
        assert np.allclose(np.linalg.det(T[:, :3, :3]), 1.0)
        d = T[:, :3, :3] @ a  # the approach direction in the world
        side, top = d[:8], d[8:]
        assert np.allclose(side[:, 2], 0.0, atol=1e-12) and np.allclose(top, [0, 0, -1], atol=1e-12)
        yaws = np.arange(8) * 2 * math.pi / 8
        assert np.allclose(side[:, :2], np.c_[np.cos(yaws), np.sin(yaws)], atol=1e-12)
        # the TCP stands 0.1 m back from the object (the top grasps at the object's height)
        assert np.allclose(T[:8, :3, 3] + 0.1 * side, p_o, atol=1e-12)
        assert np.allclose(T[8:, :3, 3] + 0.1 * top, p_o, atol=1e-12)


def test_surface_map_counts_only_bins_whose_approach_points_down():
    from baseplace.placement.surface_map import allowed_bins
    from baseplace.reachability.build import BuildSettings, build_map

    robot = Robot(EXAMPLES / "ur5_base.toml")
    rmap = build_map(robot, None, BuildSettings(samples=20_000, seed=0))
    R = rmap.grid.orientation_centre(np.arange(rmap.grid.n_orientations))
    for axis in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        ok = allowed_bins(rmap, math.pi / 4, axis)
        down = np.einsum("nij,j->ni", R, axis) @ np.array([0.0, 0.0, -1.0])  # rotate, then compare with -z
        assert np.array_equal(ok, down >= math.cos(math.pi / 4))
    assert np.array_equal(
        allowed_bins(rmap, math.pi / 4, "z"), allowed_bins(rmap, math.pi / 4, robot.arm().approach_axis)
    )


def test_candidates_grasps_approach_along_the_robot_files_axis(tmp_path):
    """Through the CLI: every grasp of a UR5 candidate points tool0's z (its approach) at the object."""
    from conftest import SHARED

    rmap = tmp_path / "ur5.rmap"
    proc = run(
        "build-map", "--robot", str(EXAMPLES / "ur5_base.toml"), "--samples", "3e6", "--out", str(rmap)
    )
    assert proc.returncode == 0, proc.stderr
    p_o = np.array([-1.025, -0.775, 0.6])
    occupancy = str(SHARED / "maps" / "tb3_sandbox.yaml")
    proc = run("candidates", "--robot", str(EXAMPLES / "ur5_base.toml"), "--map", str(rmap), "--occupancy", occupancy,
               "--object", "-1.025 -0.775 0.6", "--standoff", "0.1", "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    candidates = json.loads(proc.stdout)["candidates"]
    assert candidates
    robot = Robot(EXAMPLES / "ur5_base.toml")
    arm = robot.arm()
    for c in candidates:
        G = np.asarray(c["grasp"])
        z = G[:3, 2]
        to_object = (p_o - G[:3, 3]) / max(np.linalg.norm(p_o - G[:3, 3]), 1e-12)
        side = abs(z[2]) < 1e-4 and np.allclose(z, to_object, atol=1e-4)
        top = np.allclose(z, [0, 0, -1], atol=1e-4)
        assert side or top, z
        # the arm's FK (checked against pinocchio above) puts tool0 on the grasp from the candidate's joints
        T = forward_kinematics(arm, np.array([[c["joints"][j] for j in arm.joint_names]]))[0]
        base = np.array([[math.cos(c["yaw"]), -math.sin(c["yaw"]), 0, c["x"]],
                         [math.sin(c["yaw"]), math.cos(c["yaw"]), 0, c["y"]], [0, 0, 1, 0], [0, 0, 0, 1]])  # fmt: skip
        assert np.allclose((base @ T)[:3, 3], G[:3, 3], atol=2e-3)


def test_surface_map_reads_the_arms_approach_axis():
    import dataclasses

    from baseplace.placement.surface_map import build_surface_map
    from baseplace.reachability.build import BuildSettings, build_map

    robot_z = Robot(EXAMPLES / "ur5_base.toml")
    spec = robot_z.spec
    spec_x = dataclasses.replace(spec, arms={"arm": dataclasses.replace(spec.arms["arm"], approach="x")})
    robot_x = Robot(spec_x)
    rmap = build_map(robot_z, None, BuildSettings(samples=300_000, seed=0))
    polygon = "0,0;0.8,0;0.8,0.5;0,0.5"
    smap_z = build_surface_map(robot_z, {"arm": rmap}, polygon, 0.6, 0.1, 8)
    smap_x = build_surface_map(robot_x, {"arm": rmap}, polygon, 0.6, 0.1, 8)
    assert smap_z.values.max() > 0 and not np.array_equal(smap_z.values, smap_x.values)


def test_rotation_taking_one_direction_onto_another():
    from baseplace.geometry.poses import rotation_taking

    rng = np.random.default_rng(3)
    pairs = [(rng.normal(size=3), rng.normal(size=3)) for _ in range(200)]
    pairs += [(np.array(v), -np.array(v)) for v in ([1.0, 0, 0], [0, 0, 1.0], [0.3, -0.2, 0.9])]
    pairs += [(np.array([0, 0, 2.0]), np.array([0, 0, 1.0]))]
    for a, b in pairs:
        R = rotation_taking(a, b)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(R), 1.0)
        assert np.allclose(R @ (a / np.linalg.norm(a)), b / np.linalg.norm(b), atol=1e-12)
    with pytest.raises(InputError, match="non-zero 3-vector"):
        rotation_taking([0, 0, 0], [1, 0, 0])


@pytest.mark.parametrize(("approach", "flagged"), [("y", False), ("z", True), ("-y", True)])
def test_approach_check_when_the_tcp_sits_on_the_wrist(tmp_path, approach, flagged):
    """TCP = wrist_3_link, at the last joint: the hand's geometry (towards tool0, along its y) decides."""
    text = (EXAMPLES / "ur5_base.toml").read_text()
    text = text.replace('tcp_frame = "tool0"', 'tcp_frame = "wrist_3_link"').replace(
        'approach = "z"', f'approach = "{approach}"'
    )
    (tmp_path / "w3.toml").write_text(text)
    warnings = [w for w in check_robot(Robot(tmp_path / "w3.toml")).warnings if "approach" in w]
    assert bool(warnings) == flagged
    if flagged:
        assert 'set approach = "y"' in warnings[0]


def _pinocchio_touching_links(urdf: Path, joints: dict[str, float]) -> set[frozenset[str]]:
    """The link pairs coal finds touching with every geometry pair enabled, on the unmounted URDF.

    Pairs of geometry on one joint (fixed joints between) are left out: no configuration moves
    them apart, so no self-collision checker tests them.
    """
    model = pin.buildModelFromUrdf(str(urdf))
    geom = pin.buildGeomFromUrdf(
        model, str(urdf), pin.COLLISION, package_dirs=[str(example_robot_data_dir())]
    )
    geom.addAllCollisionPairs()
    geom_data = pin.GeometryData(geom)
    pin.computeCollisions(model, model.createData(), geom, geom_data, _pinocchio_q(model, joints), False)
    objects, frames = geom.geometryObjects, model.frames
    return {
        frozenset((frames[objects[p.first].parentFrame].name, frames[objects[p.second].parentFrame].name))
        for p, res in zip(geom.collisionPairs, geom_data.collisionResults, strict=True)
        if res.isCollision() and objects[p.first].parentJoint != objects[p.second].parentJoint
    }


def test_robot_check_names_the_pairs_in_self_collision_and_prints_the_srdf_lines_that_fix_it(tmp_path):
    """Kinova's SRDF disables nothing: its adjacent links touch at the reference configuration."""
    robot_file = _kinova_file(tmp_path)
    expected = _pinocchio_touching_links(KINOVA_URDF, KINOVA_REFERENCE)
    assert len(expected) >= 2, expected
    proc = run("robot", "check", str(robot_file), "--png", str(tmp_path / "k.png"), "--json")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    [warning] = [w for w in report["warnings"] if "self-collision" in w]
    named = re.search(r"in self-collision: (.*?); disable these pairs in the robot's SRDF", warning)
    assert named, warning
    pairs = [re.fullmatch(r"(\S+) - (\S+) \(([0-9.]+) mm deep\)", p) for p in named.group(1).split(", ")]
    assert all(pairs) and {frozenset(m.group(1, 2)) for m in pairs if m} == expected, warning
    assert "[reference]" in warning
    touching = report["collision"]["colliding_at_reference"]
    assert {frozenset((c["link1"], c["link2"])) for c in touching} == expected
    assert all(0 < c["depth_m"] < 0.01 and c["adjacent"] for c in touching)
    fix = report["collision"]["srdf_fix"]
    for pair in expected:  # each touching pair, ready to paste, first
        a, b = sorted(pair)
        assert any(f'"{a}"' in line and f'"{b}"' in line and 'reason="Adjacent"' in line
                   for line in fix[: len(expected)]), fix  # fmt: skip
    # the text output (what the command prints without --json) has the same lines
    text = report_text(report).splitlines()
    assert f"warning: {warning}" in text and [f"  {line}" for line in fix] == text[-len(fix) :]
    # pasted into a copy of the SRDF, they fix it
    srdf = tmp_path / "kinova_fixed.srdf"
    srdf.write_text(KINOVA_SRDF.read_text().replace("</robot>", "\n".join(fix) + "\n</robot>"))
    fixed = check_robot(Robot(_kinova_file(tmp_path, srdf, "kinova_fixed")))
    assert not [w for w in fixed.warnings if "self-collision" in w], fixed.warnings
    assert fixed.collision["pairs"] == report["collision"]["pairs"] - len(fix)
    assert fixed.collision["colliding_at_reference"] == [] and fixed.collision["srdf_fix"] == []


def _docs_python_block(containing: str) -> str:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "robots.md").read_text(), re.S)
    [block] = [b for b in blocks if containing in b]
    return block


def test_the_docs_pinocchio_check_handles_continuous_joints(tmp_path):
    """docs/robots.md's tcp_in_world on a Kinova against baseplace's FK (its own chain kernel)."""
    namespace: dict[str, object] = {}
    exec(_docs_python_block("def tcp_in_world"), namespace)
    tcp_in_world = namespace["tcp_in_world"]
    robot_file = _kinova_file(tmp_path)
    arm = Robot(robot_file).arm()
    assert arm.continuous.sum() == 3
    rng = np.random.default_rng(11)
    Q = arm.sample(rng, 40)
    assert np.abs(Q[:, arm.continuous]).max() > 2.0  # angles far from 0, where one slot is far off
    for q, (x, y, yaw) in zip(Q, rng.uniform([-3, -3, -math.pi], [3, 3, math.pi], (len(Q), 3)), strict=True):
        T_world_base = np.array([[math.cos(yaw), -math.sin(yaw), 0, x], [math.sin(yaw), math.cos(yaw), 0, y],
                                 [0, 0, 1, 0], [0, 0, 0, 1]])  # fmt: skip
        placement = {  # as `place --json` writes one: joints to 6 decimals
            "base_pose": np.round(T_world_base, 6).tolist(),
            "joints": [dict(zip(arm.joint_names, np.round(q, 6).tolist(), strict=True))],
        }
        T_docs = tcp_in_world(str(robot_file), placement, arm.tcp_frame)  # type: ignore[operator]
        expected = T_world_base @ forward_kinematics(arm, q[None])[0]
        assert np.abs(T_docs[:3, 3] - expected[:3, 3]).max() < 1e-3
        assert np.abs(T_docs[:3, :3] - expected[:3, :3]).max() < 1e-3


LOW_RECALL, LOW_PRECISION, LOW_ROBUSTNESS = 0.95, 0.85, 0.8  # as docs/maps.md and docs/placement.md say


def _measured(stdout: str) -> tuple[float, float]:
    m = re.search(r"measured: recall ([0-9.]+)% on \d+ FK poses, precision ([0-9.]+)%", stdout)
    assert m, stdout
    return float(m.group(1)) / 100, float(m.group(2)) / 100


def test_build_map_prints_a_hint_below_the_documented_recall_and_precision(tmp_path):
    """TIAGo, 2e6 samples in 0.1 m voxels: with the support test's threshold 0.8 the recall is low
    (88 %); at threshold 0.05 the recall is back above 95 % and the precision low (84 %)."""
    hints = []
    for threshold in ("0.8", "0.05"):
        proc = run("build-map", "--samples", "2e6", "--voxel-size", "0.1", "--support-threshold", threshold,
                   "--out", str(tmp_path / f"t{threshold}.rmap"))  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        recall, precision = _measured(proc.stdout)
        recall_hint = [line for line in proc.stdout.splitlines() if line.startswith("hint: recall")]
        precision_hint = [line for line in proc.stdout.splitlines() if line.startswith("hint: precision")]
        assert len(recall_hint) == (recall < LOW_RECALL) and len(precision_hint) == (
            precision < LOW_PRECISION
        )
        for line in recall_hint:
            assert f"recall {recall:.1%} is low (below 95%)" in line and line.endswith("(--samples 2e8)")
        for line in precision_hint:
            assert f"precision {precision:.1%} is low (below 85%)" in line and "finer cells" in line
        hints += recall_hint + precision_hint
    assert [h.split()[1] for h in hints] == ["recall", "precision"], hints  # one of each fired


def test_place_prints_a_hint_below_the_documented_robustness(tmp_path):
    cloud, rmap = tmp_path / "flat.ply", tmp_path / "tiago.rmap"
    assert run("scene", "generate", "--planes", "0", "--no-box", "--extent", "6", "--seed", "2",
               "--out", str(cloud)).returncode == 0  # fmt: skip
    assert run("build-map", "--samples", "5e6", "--out", str(rmap)).returncode == 0
    args = ["place", "--cloud", str(cloud), "--target", "1.0 0.5 0.75 0 1.5708 0", "--map", str(rmap),
            "--placements", "2", "--tries", "200", "--no-motion-check"]  # fmt: skip
    rates = {}
    for extra in ([], ["--rank-by-robustness", "--min-robustness", str(LOW_ROBUSTNESS)]):
        proc = run(*args, *extra)
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.splitlines()
        shown = [float(r) for r in re.findall(r"robustness ([0-9.]+) \[", proc.stdout)]
        hint = [line for line in lines if line.startswith("hint:")]
        assert len(shown) == 2 and len(hint) == (min(shown) < LOW_ROBUSTNESS), proc.stdout
        if hint:
            assert hint[0].startswith(f"hint: robustness {min(shown):.2f} is low (below 0.8)")
            assert f"fails from {1 - min(shown):.0%} of the drawn base stops" in hint[0]
        rates[bool(extra)] = min(shown)
    assert rates[False] < LOW_ROBUSTNESS <= rates[True]  # the hint fired, and --min-robustness silenced it
