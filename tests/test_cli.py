from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA
from conftest import run_cli as run


def assert_one_line_error(proc: subprocess.CompletedProcess[str], code: int, *fragments: str) -> None:
    assert proc.returncode == code, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.fixture(scope="module")
def map_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("maps") / "planar3.rmap"
    proc = run("build-map", "--robot", str(DATA / "planar3.toml"), "--samples", "2e5", "--out", str(path),
               "--seed", "1", "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["samples"] == 200_000 and out["cells_reached"] > 0 and proc.stderr == ""
    return path


COMMANDS = ("robots", "build-map", "reach", "place", "candidates", "navigate", "surface-map", "surface-sample",
            "occupancy", "segment", "scene", "experiment", "demo")  # fmt: skip


def test_help_lists_every_command_on_one_line():
    proc = run("--help")
    assert proc.returncode == 0
    lines = proc.stdout.splitlines()
    for command in COMMANDS:  # the name and its help text on the same line
        assert any(line.split()[:1] == [command] and len(line.split()) > 2 for line in lines), command


def test_robots_json():
    proc = run("robots", "--json")
    robots = {r["name"]: r for r in json.loads(proc.stdout)["robots"]}
    assert set(robots) == {"tiago", "pr2", "tiago_dual"}
    assert robots["tiago"]["arms"]["arm"]["tcp_frame"] == "arm_tool_link"
    assert set(robots["pr2"]["arms"]) == {"left", "right"}


def test_reach_single_and_batch(map_file, tmp_path):
    # Target: the planar3 TCP at joint values (0.2, 0.3, -0.4, 0.5), from a pinocchio oracle.
    import numpy as np
    import pinocchio as pin

    from baseplace.geometry.poses import matrix_to_rpy
    from baseplace.robots.model import Robot

    robot = Robot(DATA / "planar3.toml")
    arm = robot.arm()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio([0.2, 0.3, -0.4, 0.5], robot.q_reference))
    T = data.oMf[robot.model.getFrameId("tool0")].homogeneous
    # Put the base at (1, 2, yaw 0.7): the world target is T_world_base @ T_base_tcp.
    c, s = np.cos(0.7), np.sin(0.7)
    T_wb = np.array([[c, -s, 0, 1.0], [s, c, 0, 2.0], [0, 0, 1, 0], [0, 0, 0, 1]])
    T_w = T_wb @ T
    target = " ".join(f"{v:.12f}" for v in [*T_w[:3, 3], *matrix_to_rpy(T_w[:3, :3])])
    proc = run("reach", "--map", str(map_file), "--target", target, "--base", "1 2 0.7", "--json")
    assert proc.returncode == 0, proc.stderr
    value = json.loads(proc.stdout)["values"][0]
    assert value > 0
    far = run(
        "reach", "--map", str(map_file), "--target", target, "--base", "9 9 0"
    )  # every value would be 0
    assert_one_line_error(far, 2, "beyond the arm's reach from --base", "coordinates are in metres")

    (tmp_path / "t.txt").write_text(f"{target}\n# comment\n{target}\n")
    (tmp_path / "b.txt").write_text("1 2 0.7\n9 9 0\n")
    proc = run("reach", "--map", str(map_file), "--targets", str(tmp_path / "t.txt"), "--bases",
               str(tmp_path / "b.txt"), "--json")  # fmt: skip
    assert json.loads(proc.stdout)["values"] == [value, 0.0]
    proc = run(
        "reach",
        "--map",
        str(map_file),
        "--target",
        target,
        "--bases",
        str(tmp_path / "b.txt"),
        "--json",
    )
    assert json.loads(proc.stdout)["values"] == [value, 0.0]


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["reach", "--target", "1 2 nan 0 0 0", "--base", "0 0 0"], ["NaN"]),
        (["reach", "--target", "1 2 3", "--base", "0 0 0"], ["6 numbers"]),
        (["reach", "--target", "1 2 3 0 0 0", "--base", "0 0 0", "--robot", "tiago"],
         ["built for robot 'planar3', not 'tiago'"]),
        (["reach", "--target", "1 2 3 0 0 0", "--base", "0 0 0", "--robot", "rover"], ["unknown robot", "tiago"]),
        (["reach", "--base", "0 0 0"], ["exactly one of --target or --targets"]),
    ],
)  # fmt: skip
def test_reach_bad_input(map_file, args, fragments):
    assert_one_line_error(run(*args[:1], "--map", str(map_file), *args[1:]), 2, *fragments)


def test_truncated_map_and_mismatched_files(map_file, tmp_path):
    bad = tmp_path / "bad.rmap"
    bad.write_bytes(map_file.read_bytes()[:1000])
    assert_one_line_error(run("reach", "--map", str(bad), "--target", "1 2 3 0 0 0", "--base", "0 0 0"), 2,
                          "truncated or corrupt")  # fmt: skip
    (tmp_path / "t.txt").write_text("0 0 0 0 0 0\n0 0 0 0 0 0\n0 0 0 0 0 0\n")
    (tmp_path / "b.txt").write_text("0 0 0\n0 0 0\n")
    assert_one_line_error(run("reach", "--map", str(map_file), "--targets", str(tmp_path / "t.txt"), "--bases",
                              str(tmp_path / "b.txt")), 2, "pair row by row")  # fmt: skip


def test_build_map_bad_input(tmp_path):
    out = str(tmp_path / "m.rmap")
    assert_one_line_error(
        run("build-map", "--robot", "tiagoo", "--out", out), 2, "unknown robot", "pr2, tiago"
    )
    assert_one_line_error(run("build-map", "--samples", "-5", "--out", out), 2, "--samples")
    assert_one_line_error(run("build-map", "--samples", "1e3", "--out", str(tmp_path / "no" / "m.rmap")), 2,
                          "does not exist")  # fmt: skip
    assert_one_line_error(run("build-map", "--robot", "pr2", "--arm", "middle", "--samples", "10", "--out", out), 2,
                          "unknown arm", "left, right")  # fmt: skip
    assert_one_line_error(run("build-map", "--samples", "10", "--workers", "0", "--out", out), 2, "--workers")
    assert_one_line_error(run("build-map", "--support-threshold", "2", "--out", out), 2,
                          "support threshold must be in [0, 1]", "0: off")  # fmt: skip
    assert_one_line_error(
        run("build-map", "--support-threshold", "abc", "--out", out), 2, "--support-threshold"
    )
    (tmp_path / "broken.urdf").write_text((DATA / "broken.urdf").read_text())
    robot = tmp_path / "r.toml"
    robot.write_text('name = "b"\nurdf = "broken.urdf"\nbase_frame = "a"\nfootprint = { radius = 0.2 }\n'
                     '[arms.arm]\njoints = ["j"]\ntcp_frame = "a"\n')  # fmt: skip
    assert_one_line_error(run("build-map", "--robot", str(robot), "--samples", "10", "--out", out), 2,
                          "cannot parse URDF")  # fmt: skip
    (tmp_path / "broken.urdf").write_text((DATA / "missing_link.urdf").read_text())  # valid XML, bad model
    assert_one_line_error(run("build-map", "--robot", str(robot), "--samples", "10", "--out", out), 2,
                          "cannot parse URDF")  # fmt: skip
    assert not (tmp_path / "m.rmap").exists()
    robot.write_text('name = "b"\nurdf = "planar3.urdf"\nbase_frame = "base_link"\nfootprint = { radius = 0.2 }\n'
                     '[arms.arm]\njoints = ["joint1"]\ntcp_frame = "gripper"\n')  # fmt: skip
    (tmp_path / "planar3.urdf").write_text((DATA / "planar3.urdf").read_text())
    assert_one_line_error(run("build-map", "--robot", str(robot), "--samples", "10", "--out", out), 2,
                          "unknown TCP frame 'gripper'", "tool0")  # fmt: skip
    robot.write_text(robot.read_text().replace('"gripper"', '"tool0"').replace('["joint1"]', '["elbow"]'))
    assert_one_line_error(run("build-map", "--robot", str(robot), "--samples", "10", "--out", out), 2,
                          "unknown joint 'elbow'", "joint1")  # fmt: skip
    assert_one_line_error(run("frobnicate"), 2, "invalid choice")


def test_demo_places_on_the_platform_and_drives_up_the_ramp(tmp_path):
    import numpy as np
    import pinocchio as pin

    from baseplace.geometry.poses import parse_pose6
    from baseplace.robots.model import Robot

    # the user's cache: the default map is built once for this test and the README's commands
    proc = subprocess.run(
        [sys.executable, "-m", "baseplace.cli", "demo", "--samples", "1e7", "--out", str(tmp_path / "out"), "--json"],
        capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert json.loads((tmp_path / "out" / "demo.json").read_text()) == result
    import jsonschema

    from baseplace.jobs import result_schema

    jsonschema.validate(result, result_schema())
    assert (tmp_path / "out" / "demo.png").stat().st_size > 10_000
    p = result["placement"]
    # On the platform (the generator's truth: 0.3 m high, x 0.3..2.9, y -1.3..1.3), level.
    assert p["z"] == pytest.approx(0.3, abs=0.03) and 0.3 < p["x"] < 2.9 and abs(p["y"]) < 1.3
    # Oracle: pinocchio FK of the reported joints, at the reported base pose, hits the target.
    robot = Robot("tiago")
    arm = robot.arm()
    q = arm.to_pinocchio([p["joints"][j] for j in arm.joint_names], robot.q_reference)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    T_base_tcp = data.oMf[robot.model.getFrameId(arm.tcp_frame)].homogeneous  # base_footprint is the root
    T_world_tcp = np.asarray(p["base_pose"]) @ T_base_tcp
    np.testing.assert_allclose(T_world_tcp[:3, 3], parse_pose6(result["targets"][0])[:3, 3], atol=2e-4)
    # The path starts at the start on the floor, ends at the placement and goes up the ramp.
    route = result["path"]
    assert route["poses"][0][:2] == [-3.5, 0.0]
    assert route["poses"][-1][:2] == pytest.approx([p["x"], p["y"]], abs=1e-3)
    assert len(route["regions"]) == 3 and route["regions"][-1] == p["region"]


def test_scene_generate_and_segment(tmp_path):
    cloud = tmp_path / "scene.ply"
    proc = run(
        "scene",
        "generate",
        "--size-class",
        "small",
        "--planes",
        "2",
        "--seed",
        "4",
        "--out",
        str(cloud),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert Path(info["outputs"]["truth"]).is_file() and info["planes"] == 2
    png = tmp_path / "regions.png"
    proc = run("segment", str(cloud), "--out", str(png), "--json")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert len(result["regions"]) >= 3 and png.stat().st_size > 5000
    truth = json.loads(Path(info["outputs"]["truth"]).read_text())
    found = [r["normal"] for r in result["regions"]]
    for plane in truth["planes"]:  # every true plane has a region with its normal (within 1 deg)
        best = max(float(np.dot(plane["normal"], n)) for n in found)
        assert best > np.cos(np.radians(1.0))
    assert {"p_s", "p_e", "traversable"} <= set(result["edges"][0])


@pytest.mark.parametrize(
    ("make", "fragments"),
    [
        (
            lambda p: p.write_text(
                "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                "property float z\nend_header\n"
            ),
            ["no finite points", "0 points"],
        ),
        (lambda p: np.save(p.with_suffix(".npy"), np.full((10, 3), np.nan)), ["no finite points"]),
    ],
)
def test_segment_bad_clouds(tmp_path, make, fragments):
    path = tmp_path / "c.ply"
    make(path)
    target = path if path.exists() else path.with_suffix(".npy")
    assert_one_line_error(run("segment", str(target)), 2, *fragments)


def test_segment_bad_arguments(tmp_path):
    cloud = tmp_path / "scene.npy"
    np.save(cloud, np.c_[np.random.default_rng(0).uniform(0, 3, (20000, 2)), np.zeros(20000)])
    assert_one_line_error(run("segment", str(cloud), "--resolution", "1e-5"), 2, "resolution")
    assert_one_line_error(run("segment", str(cloud), "--transform", "1 0 0"), 2, "up direction")
    assert_one_line_error(run("segment", str(cloud), "--transform", "0 0 0"), 2)
    assert_one_line_error(run("segment", str(cloud), "--algorithm", "ransac"), 2, "invalid choice")
    assert_one_line_error(
        run("scene", "generate", "--size-class", "huge", "--out", str(tmp_path / "s.ply")), 2
    )
    assert_one_line_error(run("segment", str(tmp_path / "missing.pcd")), 2, "does not exist")
    # no cloud: the message names segment's own argument; --cloud is not taken for --cloud-topic
    assert_one_line_error(run("segment"), 2, "baseplace segment CLOUD", "--bag")
    assert_one_line_error(run("segment", "--cloud", str(cloud)), 2, "unrecognized arguments: --cloud")
    assert_one_line_error(run("segment", str(cloud), "--resol", "0.05"), 2, "unrecognized arguments: --resol",
                          "see 'baseplace segment --help'")  # fmt: skip
    assert_one_line_error(run("scene", "generate", "--out", str(tmp_path / "s.ply"), "--bogus"), 2,
                          "unrecognized arguments: --bogus", "see 'baseplace scene generate --help'")  # fmt: skip


def test_place_command(tmp_path):
    cloud = tmp_path / "flat.ply"
    assert (
        run(
            "scene",
            "generate",
            "--planes",
            "0",
            "--no-box",
            "--extent",
            "6",
            "--seed",
            "2",
            "--out",
            str(cloud),
        ).returncode
        == 0
    )
    map_file = tmp_path / "tiago.rmap"
    assert run("build-map", "--samples", "5e6", "--out", str(map_file)).returncode == 0
    png = tmp_path / "place.png"
    target = "1.0 0.5 0.75 0 1.5708 0"
    proc = run("place", "--cloud", str(cloud), "--target", target, "--map", str(map_file), "--placements", "2",
               "--tries", "200", "--out", str(png), "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["robot"]["tcp_frames"] == {"arm": "arm_tool_link"} and len(out["placements"]) == 2
    placement = out["placements"][0]
    assert set(placement) >= {"base_pose", "x", "y", "z", "yaw", "region", "reachability", "joints"}
    assert set(out["timings_ms"]) >= {"segmentation", "osrm", "query", "total"}
    assert len(placement["joints"]) == 1 and "arm_1_joint" in placement["joints"][0]
    assert png.stat().st_size > 5000
    # With --start, every placement comes with a collision-free path from the start to it.
    proc = run("place", "--cloud", str(cloud), "--target", target, "--map", str(map_file), "--tries", "200",
               "--start", "-2 -2 0", "--planner", "regions", "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    route = out["placements"][0]["path"]
    assert (
        route["poses"][0] == [-2.0, -2.0, 0.0] and route["length"] > 3.0 and "navigation" in out["timings_ms"]
    )
    end = route["poses"][-1]
    assert end[:2] == pytest.approx([out["placements"][0]["x"], out["placements"][0]["y"]], abs=1e-3)
    assert_one_line_error(run("place", "--cloud", str(cloud), "--target", target, "--map", str(map_file),
                              "--start", "9 9 0"), 2, "--start", "outside the scanned area")  # fmt: skip
    # Out of reach (3.5 m up): refused before the search, with how far (tests/test_input_units.py).
    proc = run("place", "--cloud", str(cloud), "--target", "1.0 0.5 3.5 0 0 0", "--map", str(map_file))
    assert_one_line_error(proc, 2, "m higher than tiago's 'arm' arm reaches")
    # Within the arm's bound but unreachable in this scene (1.85 m up, an arm tilted down): exit 3 with the counts.
    proc = run("place", "--cloud", str(cloud), "--target", "1.0 0.5 1.85 0 1.5708 0", "--map", str(map_file),
               "--tries", "20")  # fmt: skip
    assert_one_line_error(proc, 3, "no verified placement", "failures")
    # A top-down grasp at 1.2 m: IK reaches it from some base poses, the pre-grasp 0.15 m above it from none
    # (tests/test_motion.py); the error line and the JSON say why the motion failed.
    proc = run("place", "--cloud", str(cloud), "--target", "1.0 0.5 1.2 0 1.5708 0", "--map", str(map_file),
               "--tries", "20", "--json")  # fmt: skip
    assert proc.returncode == 3, proc.stderr
    out = json.loads(proc.stdout)
    assert "no reaching motion: the straight approach leaves the arm's reach" in out["error"]
    assert out["motion_failures"]["approach_ik"] > 0
    assert sum(out["motion_failures"].values()) == out["failures"]["motion"]
    # a contact in the approach is named after the more frequent motion reasons
    if "most often link" in out["error"]:
        assert out["failures"]["motion"] > out["failures"].get("collision", 0)
        assert out["error"].index("no reaching motion") < out["error"].index("most often link")
    # A map of another robot is refused.
    assert_one_line_error(run("place", "--robot", "pr2", "--cloud", str(cloud), "--target", target, "--map",
                              str(map_file)), 2, "built for robot 'tiago'")  # fmt: skip
    assert_one_line_error(run("place", "--cloud", str(cloud), "--map", str(map_file)), 2, "--target")


@pytest.fixture(scope="module")
def surface_cli(tmp_path_factory):
    """Runs the CLI with its own cache, so that the small maps of these tests stay out of the user's."""
    cache = tmp_path_factory.mktemp("surface") / "kernels"

    def call(*args: str) -> subprocess.CompletedProcess[str]:
        return run(*args, env={"BASEPLACE_CACHE": str(cache)})

    return call


def test_surface_map_and_sample_commands(surface_cli, tmp_path):
    smap = tmp_path / "table.smap"
    common = ("--robot", "tiago", "--samples", "3e5", "--height", "0.7", "--resolution", "0.1",
              "--orientations", "8")  # fmt: skip
    proc = surface_cli(
        "surface-map", *common, "--polygon", "0,0;1.2,0;1.2,0.6;0,0.6", "--out", str(smap), "--json"
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["file_bytes"] == smap.stat().st_size and out["nonzero_poses"] > 0 and 0 < out["max"] <= 1
    assert out["arms"] == ["arm"] and out["orientations"] == 8
    proc = surface_cli("surface-sample", "--map", str(smap), "--n", "3", "--candidates", "5", "--json")
    assert proc.returncode == 0, proc.stderr
    poses = json.loads(proc.stdout)["poses"]
    assert len(poses) == 3 and all(p["reachability"] > 0 for p in poses)
    # an occupancy grid with no free cell excludes every pose
    (tmp_path / "full.pgm").write_bytes(b"P5 20 20 255\n" + bytes(400))
    (tmp_path / "full.yaml").write_text("image: full.pgm\nresolution: 0.5\norigin: [-5, -5, 0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    proc = surface_cli("surface-sample", "--map", str(smap), "--occupancy", str(tmp_path / "full.yaml"))
    assert_one_line_error(proc, 2, "leaves no free pose")
    bad = tmp_path / "bad.smap"
    proc = surface_cli("surface-map", *common, "--polygon", "0,0;1,1;1,0;0,1", "--out", str(bad))
    assert_one_line_error(proc, 2, "not simple")
    proc = surface_cli(
        "surface-map", *common, "--arms", "left", "--polygon", "0,0;1,0;1,1", "--out", str(bad)
    )
    assert_one_line_error(proc, 2, "unknown arm 'left'", "valid: any, arm, both")
    proc = surface_cli(
        "surface-map", *common, "--arms", "both", "--polygon", "0,0;1,0;1,1", "--out", str(bad)
    )
    assert_one_line_error(proc, 2, "needs two arms")
    assert not bad.exists()


def test_occupancy_command_prints_map_server_values():
    from conftest import SHARED
    from test_occupancy import EXPECTED

    proc = run("occupancy", str(SHARED / "maps" / "nav2_testmap" / "testmap.yaml"), "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert (out["width"], out["height"], out["resolution"], out["origin"]) == (10, 10, 0.1, [2.0, 3.0, 1.0])
    assert out["data"] == EXPECTED.ravel().tolist()
    proc = run("occupancy", str(SHARED / "maps" / "missing.yaml"))
    assert_one_line_error(proc, 2, "missing.yaml")


def test_navigate_command(tmp_path):
    from test_navigation import _ramp_scene

    cloud = tmp_path / "ramp.npy"
    np.save(cloud, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))
    png = tmp_path / "path.png"
    proc = run("navigate", "--cloud", str(cloud), "--start", "-2 0.6 0", "--goal", "1.7 0.6 0", "--planner",
               "regions", "--out", str(png), "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["poses"][0][:2] == [-2.0, 0.6] and out["poses"][-1][:2] == [1.7, 0.6]
    assert len(out["regions"]) == 2 and out["length"] > 3.7 and png.stat().st_size > 10_000
    proc = run(
        "navigate",
        "--cloud",
        str(cloud),
        "--start",
        "-2 -1.9 0",
        "--goal",
        "0.5 -1.9 0",
        "--time-limit",
        "0.3",
    )
    assert_one_line_error(proc, 3, "no path")
    proc = run("navigate", "--cloud", str(cloud), "--start", "-0.7 -1.9 0", "--goal", "0.5 -1.9 0")
    assert_one_line_error(proc, 2, "start", "in collision")
    proc = run("navigate", "--cloud", str(cloud), "--start", "0.7 0.6 0", "--goal", "-2 0.6 0")
    assert_one_line_error(proc, 2, "off every surface")


@pytest.fixture(scope="module")
def tiago_map_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tiago") / "tiago.rmap"
    assert run("build-map", "--samples", "5e6", "--seed", "4", "--out", str(path)).returncode == 0
    return path


def test_candidates_command_on_a_real_map(tiago_map_file, tmp_path):
    import pinocchio as pin

    from baseplace.geometry.poses import BasePose
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import load_occupancy
    from conftest import SHARED

    yaml = SHARED / "maps" / "tb3_sandbox.yaml"
    png = tmp_path / "cand.png"
    proc = run("candidates", "--occupancy", str(yaml), "--object", "-1.025 -0.775 0.6", "--robot-pose",
               "-1.875 0.075 0", "--map", str(tiago_map_file), "--png", str(png), "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["candidates"] and png.stat().st_size > 10_000 and out["path"] is not None
    grid = load_occupancy(yaml)
    occupied = grid.cell_to_world(np.argwhere(grid.data == 100)[:, ::-1])
    robot = Robot("tiago")
    arm = robot.arm()
    data = robot.model.createData()
    costs = [c["motion_cost"] for c in out["candidates"]]
    assert costs == sorted(costs)
    for c in out["candidates"]:
        # in free space with r_r clearance from every occupied cell (brute force over cell squares)
        gap = np.abs(occupied - [c["x"], c["y"]]) - grid.resolution / 2
        assert np.hypot(*np.maximum(gap, 0.0).T).min() >= out["settings"]["r_r"] - 1e-9
        # pinocchio FK of the verified joints reaches the reported grasp
        q = arm.to_pinocchio([c["joints"][j] for j in arm.joint_names], robot.q_reference)
        pin.framesForwardKinematics(robot.model, data, q)
        T = (
            BasePose(c["x"], c["y"], c["yaw"]).matrix()
            @ data.oMf[robot.model.getFrameId(arm.tcp_frame)].homogeneous
        )
        np.testing.assert_allclose(T[:3, 3], np.asarray(c["grasp"])[:3, 3], atol=2e-4)


def test_candidates_bad_input(tiago_map_file, tmp_path):
    from conftest import SHARED

    yaml = str(SHARED / "maps" / "tb3_sandbox.yaml")
    common = ("--map", str(tiago_map_file))
    assert_one_line_error(run("candidates", "--occupancy", yaml, "--object", "30 0 0.6", *common), 2,
                          "outside the occupancy grid")  # fmt: skip
    assert_one_line_error(run("candidates", "--occupancy", yaml, "--object", "-9 -9 0.6", *common), 2,
                          "inside an obstacle")  # fmt: skip
    assert_one_line_error(run("candidates", "--occupancy", yaml, "--object", "1 2", *common), 2, "x y z")
    (tmp_path / "bad.pgm").write_bytes(b"P5 10 10 255\n" + b"\x00" * 7)  # truncated pixels
    (tmp_path / "bad.yaml").write_text("image: bad.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                       "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    assert_one_line_error(run("candidates", "--occupancy", str(tmp_path / "bad.yaml"), "--object", "0 0 0.6",
                              *common), 2, "bad.pgm")  # fmt: skip
    (tmp_path / "short.yaml").write_text("image: bad.pgm\nresolution: 0.05\n")
    assert_one_line_error(run("candidates", "--occupancy", str(tmp_path / "short.yaml"), "--object", "0 0 0.6",
                              *common), 2, "origin")  # fmt: skip


def test_build_map_with_a_local_cluster_and_a_bad_scheduler(tmp_path, monkeypatch):
    import functools

    from baseplace.reachability import distributed
    from baseplace.reachability.storage import load_map

    args = ("build-map", "--robot", str(DATA / "planar3.toml"), "--samples", "3e6", "--seed", "5")
    assert run(*args, "--out", str(tmp_path / "one.rmap")).returncode == 0
    proc = run(*args, "--out", str(tmp_path / "two.rmap"), "--scheduler", "local", "--workers", "2", "--json")
    assert proc.returncode == 0, proc.stderr
    one, two = load_map(tmp_path / "one.rmap"), load_map(tmp_path / "two.rmap")
    np.testing.assert_array_equal(one.cells, two.cells)
    np.testing.assert_array_equal(one.counts, two.counts)
    # dask retries a refused connection until the timeout: 1 s here instead of the CLI's 10 s
    monkeypatch.setattr(distributed, "connect", functools.partial(distributed.connect, timeout_s=1.0))
    proc = run(*args, "--out", str(tmp_path / "x.rmap"), "--scheduler", "tcp://127.0.0.1:9")
    assert_one_line_error(proc, 2, "cannot connect to dask scheduler", "127.0.0.1:9", "within 1 s")
    assert not (tmp_path / "x.rmap").exists() and not (tmp_path / "x.rmap.partial").exists()


def test_inspect_table_bad_input():
    assert_one_line_error(run("experiment", "inspect-table", "--objects", "1,x"), 2, "comma-separated", "1,x")
    assert_one_line_error(run("experiment", "inspect-table", "--runs", "0"), 2, "--runs >= 1")
    assert_one_line_error(
        run("experiment", "inspect-table", "--objects", "0,9"), 2, "object counts from 1 to 8"
    )
    assert_one_line_error(run("experiment", "inspect-table", "--seed", "-1"), 2, "--seed")


def test_candidates_reaching_motion_and_robustness_in_the_json(tiago_map_file):
    from baseplace.placement.motion import stowed_configuration
    from baseplace.robots.model import Robot
    from conftest import SHARED

    yaml = str(SHARED / "maps" / "tb3_sandbox.yaml")
    common = (
        "candidates",
        "--occupancy",
        yaml,
        "--object",
        "-1.025 -0.775 0.6",
        "--map",
        str(tiago_map_file),
    )
    proc = run(*common, "--robustness-samples", "16", "--rank-by-robustness", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(proc.stdout)["candidates"]
    arm = Robot("tiago").arm()
    rates = [c["robustness"]["rate"] for c in rows]
    assert rows
    assert rates == sorted(rates, reverse=True)
    for c in rows:
        low, high = c["robustness"]["ci95"]
        assert c["robustness"]["samples"] == 16 and low <= c["robustness"]["rate"] <= high
        (m,) = c["motion"]
        np.testing.assert_allclose(m["path"][0], stowed_configuration(Robot("tiago"), arm), atol=1e-5)
        np.testing.assert_allclose(m["approach"][-1], [c["joints"][j] for j in arm.joint_names], atol=1e-5)
    proc = run(*common, "--no-motion-check", "--robustness-samples", "0", "--json")
    assert proc.returncode == 0, proc.stderr
    assert all("motion" not in c and "robustness" not in c for c in json.loads(proc.stdout)["candidates"])
    assert_one_line_error(run(*common, "--min-robustness", "1.5"), 2, "minimum robustness")
    assert_one_line_error(run(*common, "--error-model", "box", "--xy-tolerance", "0"), 2, "xy_tolerance")
    assert_one_line_error(
        run(*common, "--robustness-motion", "--no-motion-check"),
        2,
        "robustness-motion needs the motion check",
    )
