"""ROS recordings in and out: PCL clouds, a tf tree and a map_server grid written to bags and read back."""

from __future__ import annotations

import json
import math
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from baseplace.cli import main
from baseplace.errors import InputError
from baseplace.io.bag import read_bag
from baseplace.io.bag_writer import CloudRecord, GridRecord, TfRecord, write_input_bag
from baseplace.io.results import read_result_mcap
from baseplace.io.tf import TfTree
from baseplace.terrain.io import load_cloud, load_transform
from baseplace.world.occupancy import load_occupancy
from conftest import SHARED, run_cli

MUG = SHARED / "pointclouds" / "table_scene_mug_stereo_textured.pcd"
DEPOT = SHARED / "maps" / "depot.yaml"
T0 = 1_700_000_000_000_000_000  # the cloud's stamp [ns]
# The camera looks at the table from 1.27 m; the PCL reference plane puts the table 0.5287 m below
# it, so with the camera there the tabletop is 0.74 m above the depot's floor, in its largest free area.
T_MAP_CAMERA = load_transform("0.0162 -0.8378 -0.5458")
T_MAP_CAMERA[:3, 3] = [4.55, 6.98, 0.74 + 0.5287]
T_BASE_CAMERA = np.eye(4)
T_BASE_CAMERA[:3, :3] = Rotation.from_euler("xyz", [0.1, -0.3, 0.2]).as_matrix()
T_BASE_CAMERA[:3, 3] = [0.1, 0.0, 1.1]


# The target: TIAGo's hand top-down above the table top (z = 0.74), beside the mug, which stands at
# about (4.60, 7.585) with its rim at z = 0.878. TIAGo's fingers (at q_reference) reach 0.245 m beyond
# arm_tool_link, so at z = 1.02 the fingertips are 3.5 cm above the table, and the hand safety box
# (20 x 18 x 12 cm) stays clear of the mug. The reaching-motion check (on by default) needs the
# pre-grasp 0.15 m above it reachable too: the earlier target above the mug (z = 1.16) put the
# pre-grasp out of TIAGo's reach (every candidate rejected with reason motion). A grasp of the mug
# itself is blocked at every approach by a small stereo artefact 3.5 cm from the mug's nearest point,
# inside the hand safety box (docs/ros.md).
TARGET = "4.45 7.80 1.02 0 1.5708 0"


def _base_at(dx: float) -> np.ndarray:
    """T_map_base that puts the camera at T_MAP_CAMERA shifted by dx along map x."""
    T = T_MAP_CAMERA @ np.linalg.inv(T_BASE_CAMERA)
    T = T.copy()
    T[0, 3] += dx
    return T


def _write(path: Path, fmt: str) -> None:
    cloud = load_cloud(MUG)
    write_input_bag(
        path, fmt,
        clouds=[CloudRecord("/head/points", "head_camera", T0, cloud.points)],
        tf=[TfRecord("map", "base_link", T0 - 10**9, _base_at(-0.1)),  # the base drives 0.2 m in 2 s:
            TfRecord("map", "base_link", T0 + 10**9, _base_at(0.1)),  # at T0 it is half-way
            TfRecord("base_link", "head_camera", T0 - 5 * 10**9, T_BASE_CAMERA, static=True)],
        grids=[GridRecord("/map", "map", T0 - 5 * 10**9, load_occupancy(DEPOT))],
    )  # fmt: skip


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    out = {"mcap": root / "rec_mcap", "sqlite3": root / "rec_db3", "ros1": root / "rec.bag"}
    for fmt, path in out.items():
        _write(path, fmt)
    return out


@pytest.mark.parametrize("fmt", ["mcap", "sqlite3", "ros1"])
def test_read_cloud_grid_and_tf_from_every_format(bags, fmt):
    scene = read_bag(bags[fmt], ["/head/points"], "/map", "map")
    (c,) = scene.clouds
    assert c.frame == "head_camera" and c.stamp_ns == T0
    np.testing.assert_allclose(c.T_world_sensor, T_MAP_CAMERA, atol=1e-9)  # interpolated half-way
    expected = load_cloud(MUG).points @ T_MAP_CAMERA[:3, :3].T + T_MAP_CAMERA[:3, 3]
    np.testing.assert_allclose(c.world_points, expected, atol=2e-5)  # float32 in the message
    grid = load_occupancy(DEPOT)
    assert scene.grid is not None
    np.testing.assert_array_equal(scene.grid.data, grid.data)
    assert scene.grid.resolution == pytest.approx(grid.resolution) and scene.grid.origin == pytest.approx(
        grid.origin
    )


def test_tf_interpolation_against_a_hand_computed_chain():
    tree = TfTree()
    Rz = Rotation.from_euler("z", [[0.0], [1.0]])
    tree.add("map", "odom", 0, [0, 0, 0], [0, 0, 0, 1], static=True)
    tree.add("odom", "base", 0, [0, 0, 0], Rz[0].as_quat(), static=False)
    tree.add("odom", "base", 2 * 10**9, [2, 0, 0], Rz[1].as_quat(), static=False)
    tree.add("base", "cam", 0, [0.5, 0, 1], [0, 0, 0, 1], static=True)
    T = tree.lookup("map", "cam", 10**9)
    # half-way: base at x = 1, yaw 0.5; the camera 0.5 m ahead of it and 1 m up
    np.testing.assert_allclose(T[:3, 3], [1 + 0.5 * math.cos(0.5), 0.5 * math.sin(0.5), 1.0], atol=1e-12)
    np.testing.assert_allclose(tree.lookup("cam", "map", 10**9), np.linalg.inv(T), atol=1e-12)
    with pytest.raises(InputError, match=r"no transform from 'cam' to 'map' at 5.000 s.*nearest 2.000 s"):
        tree.lookup("map", "cam", 5 * 10**9)


def test_bag_errors_are_one_line_and_name_the_cause(bags, tmp_path):
    b = bags["mcap"]
    with pytest.raises(
        InputError, match=r"no topic '/points'.*topics: /head/points \(sensor_msgs/msg/PointCloud2\)"
    ):
        read_bag(b, ["/points"], None, "map")
    with pytest.raises(
        InputError, match="unknown message type nav_msgs/msg/OccupancyGrid.*expected sensor_msgs"
    ):
        read_bag(b, ["/map"], None, "map")
    with pytest.raises(
        InputError, match=r"frame 'odom' is not in /tf or /tf_static; frames: base_link, head_camera, map"
    ):
        read_bag(b, ["/head/points"], None, "odom")
    # a cloud recorded 30 s after the last /tf: the frames and the nearest stamps are named
    late = tmp_path / "late"
    write_input_bag(late, "mcap", clouds=[CloudRecord("/c", "head_camera", T0 + 30 * 10**9, np.ones((4, 3)))],
                    tf=[TfRecord("map", "base_link", T0, np.eye(4)), TfRecord("map", "base_link", T0 + 10**9, np.eye(4)),
                        TfRecord("base_link", "head_camera", T0, np.eye(4), static=True)])  # fmt: skip
    with pytest.raises(
        InputError, match=r"no transform from 'head_camera' to 'map' at .* recorded from .* nearest"
    ):
        read_bag(late, ["/c"], None, "map")
    with pytest.raises(InputError, match="does not exist"):
        read_bag(tmp_path / "missing.mcap", ["/c"], None, "map")


@pytest.fixture(scope="module")
def map_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rmap") / "tiago.rmap"
    assert main(["build-map", "--samples", "5e6", "--seed", "1", "--out", str(path)]) == 0
    return path


def test_place_from_a_bag_through_the_cli(bags, map_file, tmp_path, capsys, tiago):
    capsys.readouterr()
    out = tmp_path / "result.mcap"
    code = main(["place", "--bag", str(bags["mcap"]), "--cloud-topic", "/head/points", "--map-topic", "/map",
                 "--world-frame", "map", "--target", TARGET, "--map", str(map_file), "--placements", "2",
                 "--tries", "300", "--mcap", str(out), "--json"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    result = json.loads(captured.out)
    assert result["placements"] and result["outputs"]["mcap"] == str(out)
    assert result["object"]["allowed"] is None  # nothing at the grasp point: the hand may touch nothing
    grid = load_occupancy(DEPOT)
    arm = tiago.arm()
    geom = pin.buildGeomFromUrdf(tiago.model, str(tiago.spec.urdf), pin.COLLISION,
                                 package_dirs=[str(p) for p in tiago.spec.package_dirs])  # fmt: skip
    cloud = load_cloud(MUG).points
    cloud = cloud[np.isfinite(cloud).all(axis=1)] @ T_MAP_CAMERA[:3, :3].T + T_MAP_CAMERA[:3, 3]
    cloud_tree = coal.makeOctree(np.ascontiguousarray(cloud), 0.01)
    T_target = np.eye(4)
    T_target[:3, :3] = Rotation.from_euler("ZYX", [0.0, 1.5708, 0.0]).as_matrix()
    T_target[:3, 3] = [4.45, 7.80, 1.02]
    for p in result["placements"]:
        T = np.array(p["base_pose"])
        # the base stands on the grid's free floor: z = 0 (within a voxel) and its whole footprint free
        assert abs(T[2, 3]) < 0.03
        ring = np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 36)])
        disc = T[:2, 3] + np.vstack([r * ring for r in (0.0, 0.15, tiago.spec.footprint_radius)])
        assert grid.is_free(disc).all()
        # ... out of the table's way, which the cloud alone shows (0.6 x 0.4 m around (4.6, 7.7))
        assert not (abs(T[0, 3] - 4.6) < 0.3 and abs(T[1, 3] - 7.7) < 0.2)
        # and the arm reaches the target: pinocchio FK of the returned joints (an independent oracle)
        q = np.array([p["joints"][0][n] for n in arm.joint_names])
        data = tiago.model.createData()
        pin.framesForwardKinematics(tiago.model, data, arm.to_pinocchio(q, tiago.q_reference))
        base = data.oMf[tiago.model.getFrameId(arm.base_frame)]
        tcp = data.oMf[tiago.model.getFrameId(arm.tcp_frame)]
        reached = T @ (base.inverse() * tcp).homogeneous
        np.testing.assert_allclose(reached[:3, 3], T_target[:3, 3], atol=2e-3)
        angle = np.degrees(
            np.arccos(np.clip((np.trace(reached[:3, :3].T @ T_target[:3, :3]) - 1) / 2, -1, 1))
        )
        assert angle < 1.0
        # an independent coal check: no hand geometry touches a point of the recorded cloud (mug, table, artefact)
        gdata = pin.GeometryData(geom)
        pin.updateGeometryPlacements(tiago.model, data, geom, gdata)
        T_world_root = pin.SE3(T) * data.oMf[tiago.model.getFrameId(tiago.spec.base_frame)].inverse()
        for k, g in enumerate(geom.geometryObjects):
            if g.name.startswith("hand_"):
                M = (T_world_root * gdata.oMg[k]).homogeneous
                hit = coal.CollisionResult()
                coal.collide(g.geometry, coal.Transform3s(M[:3, :3], M[:3, 3]), cloud_tree, coal.Transform3s(),
                             coal.CollisionRequest(), hit)  # fmt: skip
                assert not hit.isCollision(), g.name
    # the MCAP holds the same poses as the JSON, in the map frame at the cloud's stamp
    msgs = read_result_mcap(out)
    poses = msgs["/baseplace/placements"]
    assert len(poses) == len(result["placements"])
    for msg, p in zip(poses, result["placements"], strict=True):
        assert msg.header.frame_id == "map" and msg.header.stamp.sec == T0 // 10**9
        q = msg.pose.orientation
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        T[:3, 3] = [msg.pose.position.x, msg.pose.position.y, msg.pose.position.z]
        np.testing.assert_allclose(T, np.array(p["base_pose"]), atol=2e-6)
    (targets,) = msgs["/baseplace/targets"]
    assert [targets.poses[0].position.x, targets.poses[0].position.y] == pytest.approx([4.45, 7.80])
    (markers,) = msgs["/baseplace/regions"]
    assert len({m.id // 100 for m in markers.markers}) == result["regions"]


def test_every_command_takes_the_bag(bags, capsys):
    capsys.readouterr()
    code = main(["segment", "--bag", str(bags["ros1"]), "--cloud-topic", "/head/points", "--json"])
    assert code == 0, capsys.readouterr().err
    regions = json.loads(capsys.readouterr().out)["regions"]
    assert any(abs(r["centroid"][2] - 0.74) < 0.02 and r["tilt_deg"] < 1.0 for r in regions)  # the table
    code = main(["segment", "--bag", str(bags["sqlite3"]), "--cloud-topic", "/nope"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no topic '/nope'" in err
    code = main(["occupancy", str(DEPOT)])  # (occupancy reads files only; surface-sample takes --bag)
    capsys.readouterr()
    assert code == 0


def test_place_from_files_camera_cloud_and_grid(map_file, tmp_path, capsys):
    # the same scene without a bag: the PCD, world_T_camera in a file, the map_server YAML
    transform = tmp_path / "map_T_camera.txt"
    transform.write_text("\n".join(" ".join(f"{v:.12g}" for v in row) for row in T_MAP_CAMERA) + "\n")
    capsys.readouterr()
    code = main(["place", "--cloud", str(MUG), "--transform", str(transform), "--occupancy", str(DEPOT),
                 "--target", TARGET, "--map", str(map_file), "--tries", "300", "--json"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    p = json.loads(captured.out)["placements"][0]
    assert abs(p["z"]) < 0.03 and load_occupancy(DEPOT).is_free(np.array([[p["x"], p["y"]]]))[0]
    # two clouds need two transforms
    code = main(["place", "--cloud", str(MUG), "--cloud", str(MUG), "--transform", str(transform),
                 "--occupancy", str(DEPOT), "--target", TARGET, "--map", str(map_file)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "one --transform per --cloud" in err


def test_segment_a_fused_bag(bags, tmp_path, capsys):
    out = tmp_path / "fused.bt"
    capsys.readouterr()
    args = [
        "segment",
        "--bag",
        str(bags["mcap"]),
        "--cloud-topic",
        "/head/points",
        "--fuse",
        "--fused-out",
        str(out),
    ]
    # a 25 mm OctoMap is too coarse for the table at the 5 cm its point spacing gives; the error says what to try
    assert main(args) == 2
    assert "try --resolution 0.03" in capsys.readouterr().err
    code = main([*args, "--resolution", "0.03", "--json"])
    assert code == 0, capsys.readouterr().err
    regions = json.loads(capsys.readouterr().out)["regions"]
    assert any(abs(r["centroid"][2] - 0.74) < 0.03 and r["tilt_deg"] < 1.0 for r in regions)  # the table
    fused = load_cloud(out).points  # 25 mm voxel centres of the camera's view: (k + 1/2) 0.025
    frac = (fused / 0.025 - 0.5) % 1.0
    assert np.all(np.minimum(frac, 1.0 - frac) < 1e-6)
    expected = load_cloud(MUG).points @ T_MAP_CAMERA[:3, :3].T + T_MAP_CAMERA[:3, 3]
    keys = {tuple(k) for k in np.floor(expected / 0.025).astype(int).tolist()}
    assert {tuple(k) for k in np.floor(fused / 0.025).astype(int).tolist()} <= keys  # one view: no new voxel


def _pose_xyyaw(pose) -> list[float]:
    q = pose.orientation
    yaw = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler("ZYX")[0]
    return [pose.position.x, pose.position.y, yaw]


def test_candidates_and_navigate_write_their_mcap(bags, map_file, tmp_path, capsys):
    out = tmp_path / "candidates.mcap"
    capsys.readouterr()
    # a grasp point over the table's left edge, 21 cm above its top: TIAGo's hand reaches 7 to 10 cm
    # below its grasp point, so 6 cm above the top (as before the table became an obstacle) it enters the table
    code = main(["candidates", "--bag", str(bags["sqlite3"]), "--map-topic", "/map", "--cloud-topic", "/head/points",
                 "--object", "4.4 7.6 0.95", "--robot-pose", "3.0 7.0 0", "--map", str(map_file),
                 "--mcap", str(out), "--json"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    rows = json.loads(captured.out)["candidates"]
    (arr,) = read_result_mcap(out)["/baseplace/candidates"]
    assert len(arr.poses) == len(rows)
    for pose, row in zip(arr.poses, rows, strict=True):
        assert _pose_xyyaw(pose) == pytest.approx([row["x"], row["y"], row["yaw"]], abs=1e-3)
    from test_navigation import _ramp_scene

    cloud = tmp_path / "ramp.npy"
    np.save(cloud, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))
    out = tmp_path / "path.mcap"
    code = main(["navigate", "--cloud", str(cloud), "--start", "-2 0.6 0", "--goal", "1.7 0.6 0", "--planner",
                 "regions", "--mcap", str(out), "--json"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    poses = json.loads(captured.out)["poses"]
    msgs = read_result_mcap(out)
    (path,) = msgs["/baseplace/path"]
    assert np.allclose([_pose_xyyaw(p.pose) for p in path.poses], poses, atol=1e-3)
    assert len(msgs["/baseplace/regions"][0].markers) >= 2  # floor and ramp outlines


def test_three_pcl_clouds_from_three_cameras(tmp_path):
    names = ("table_scene_mug_stereo_textured.pcd", "office1.pcd", "sac_plane_test.pcd")
    rng = np.random.default_rng(3)
    T_base = {}
    clouds, tf = (
        [],
        [
            TfRecord("map", "base_link", T0 - 10**9, np.eye(4)),
            TfRecord("map", "base_link", T0 + 10**9, np.eye(4)),
        ],
    )
    for k, name in enumerate(names):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
        T[:3, 3] = rng.uniform(-1, 1, 3)
        T_base[f"cam{k}"] = T
        tf.append(TfRecord("base_link", f"cam{k}", T0, T, static=True))
        points = load_cloud(SHARED / "pointclouds" / name).points
        # two messages per topic: the first at T0 - 0.5 s, the second at T0 + 0.5 s
        clouds += [
            CloudRecord(f"/cam{k}/points", f"cam{k}", T0 + s * 5 * 10**8, points[s < 0 :: 2]) for s in (-1, 1)
        ]
    path = tmp_path / "three.bag"
    write_input_bag(path, "ros1", clouds=clouds, tf=tf)
    topics = [f"/cam{k}/points" for k in range(3)]
    scene = read_bag(path, topics, None, "map", clouds="all")
    assert len(scene.clouds) == 6
    for c in scene.clouds:
        k = int(c.frame[3:])
        points = load_cloud(SHARED / "pointclouds" / names[k]).points
        first = c.stamp_ns < T0
        expected = points[first::2] @ T_base[c.frame][:3, :3].T + T_base[c.frame][:3, 3]
        np.testing.assert_allclose(c.world_points, expected, atol=1e-4)
    assert [c.stamp_ns for c in read_bag(path, topics[:1], None, "map", clouds="first").clouds] == [
        T0 - 5 * 10**8
    ]


def test_bad_messages_and_files_are_one_line_errors(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    from baseplace.io.messages import cloud_msg, cloud_points

    ts = get_typestore(Stores.ROS2_HUMBLE)
    msg = cloud_msg(ts, np.arange(12.0).reshape(4, 3), "cam", T0)
    np.testing.assert_allclose(cloud_points(msg, "t")[0], np.arange(12.0).reshape(4, 3))
    no_z = type(msg)(**{**msg.__dict__, "fields": msg.fields[:2]})
    with pytest.raises(InputError, match=r"needs float fields x, y, z; missing \['z'\]"):
        cloud_points(no_z, "t")
    short = type(msg)(**{**msg.__dict__, "data": msg.data[:20]})
    with pytest.raises(InputError, match="data of 20 bytes does not fit 4 x 1 points"):
        cloud_points(short, "t")
    garbage = tmp_path / "broken.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)))
    with pytest.raises(InputError, match="cannot read bag"):
        read_bag(garbage, ["/c"], None, "map")
    with pytest.raises(InputError, match="give a cloud topic"):
        read_bag(garbage, [], None, "map")


def test_place_with_start_plans_on_the_map_around_the_table(bags, map_file, tmp_path, capsys, tiago):
    out = tmp_path / "with_path.mcap"
    capsys.readouterr()
    args = ["place", "--bag", str(bags["mcap"]), "--cloud-topic", "/head/points", "--map-topic", "/map",
            "--target", TARGET, "--map", str(map_file), "--tries", "300"]  # fmt: skip
    code = main([*args, "--start", "5.6 9.6 0", "--mcap", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    p = json.loads(captured.out)["placements"][0]
    poses = np.array(p["path"]["poses"])
    assert poses[0].tolist() == pytest.approx([5.6, 9.6, 0.0]) and poses[-1].tolist() == pytest.approx(
        [p["x"], p["y"], p["yaw"]], abs=1e-3
    )
    # every waypoint keeps the robot's disc on free map cells and off the table the camera sees
    grid = load_occupancy(DEPOT)
    r = tiago.spec.footprint_bounding_radius
    ring = np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 24)])
    for x, y, _ in poses:
        assert grid.is_free(np.array([x, y]) + 0.9 * r * ring).all()
        # the tabletop in the map spans about [4.37, 4.83] x [7.47, 7.89] (its points' 1-99 %); one cell of slack
        gap = np.hypot(max(4.37 - x, 0.0, x - 4.83), max(7.47 - y, 0.0, y - 7.89))
        assert gap > r - 0.05
    (path,) = read_result_mcap(out)["/baseplace/path"]
    assert np.allclose([[q.pose.position.x, q.pose.position.y] for q in path.poses], poses[:, :2], atol=1e-3)
    code = main([*args, "--start", "-5 -5 0"])  # off the map
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "start" in err


@pytest.mark.slow  # ~17 s: builds a small surface map in a fresh cache
def test_surface_sample_reads_the_grid_from_the_bag(bags, tmp_path):
    import os
    import subprocess

    env = {
        **os.environ,
        "BASEPLACE_CACHE": str(tmp_path / "cache"),
    }  # small maps stay out of the user's cache

    def cli(*args: str) -> subprocess.CompletedProcess[str]:
        return run_cli(*args, env=env)

    smap = tmp_path / "table.smap"
    proc = cli("surface-map", "--robot", "tiago", "--samples", "3e5", "--height", "0.74", "--resolution", "0.1",
               "--orientations", "8", "--polygon", "4.37,7.47;4.83,7.47;4.83,7.89;4.37,7.89", "--out", str(smap))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    common = ("surface-sample", "--map", str(smap), "--n", "3", "--candidates", "5", "--json")
    from_bag = cli(*common, "--bag", str(bags["sqlite3"]), "--map-topic", "/map")
    from_file = cli(*common, "--occupancy", str(DEPOT))
    assert from_bag.returncode == 0 and from_file.returncode == 0, from_bag.stderr + from_file.stderr
    poses = json.loads(from_bag.stdout)["poses"]
    assert poses == json.loads(from_file.stdout)["poses"]  # the same grid, the same poses
    assert load_occupancy(DEPOT).is_free(np.array([[p["x"], p["y"]] for p in poses])).all()
