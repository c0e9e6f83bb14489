"""`baseplace view` on the real --json of each command: the result read, its inputs loaded, the scene
checked against independent geometry (pinocchio FK), and the page rendered by headless Chromium."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from baseplace.errors import InputError
from baseplace.geometry.poses import parse_pose6
from baseplace.robots.model import Robot
from baseplace.viz.result_view import read_result
from baseplace.viz.viewer import open_view, serve
from conftest import run_cli
from test_viewer import chromium, free_port, shoot_until

ROOT = Path(__file__).resolve().parents[1]
SHARED_MAPS = ROOT.parents[0] / "shared" / "data" / "maps"
PLACE_TARGET = "1.0 0.5 0.75 0 1.5708 0"
OBJECT = "-1.025 -0.775 0.6"


def _cli_json(out: Path, *args: str, env: dict[str, str] | None = None) -> Path:
    proc = run_cli(*args, "--json", env=env)
    assert proc.returncode == 0, proc.stderr
    out.write_text(proc.stdout)
    return out


def _with_inputs(path: Path, **inputs: str) -> Path:
    """Echo the inputs a command's JSON does not name yet (place and navigate before the one schema)."""
    obj = json.loads(path.read_text())
    echoed = obj.setdefault("inputs", {})
    for key, value in inputs.items():
        echoed.setdefault(key, value)
    path.write_text(json.dumps(obj))
    return path


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, Path]:
    """One real result of every kind the viewer shows, written by the CLI on small inputs."""
    from test_navigation import _ramp_scene

    d = tmp_path_factory.mktemp("results")
    env = {"BASEPLACE_CACHE": str(d / "cache")}
    assert (
        run_cli("build-map", "--samples", "3e6", "--seed", "4", "--out", str(d / "tiago.rmap")).returncode
        == 0
    )
    flat = d / "flat.ply"
    assert run_cli("scene", "generate", "--planes", "0", "--no-box", "--extent", "6", "--seed", "2", "--out",
                   str(flat)).returncode == 0  # fmt: skip
    ramp = d / "ramp.npy"
    np.save(ramp, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))
    out = {}
    out["place"] = _with_inputs(
        _cli_json(d / "place.json", "place", "--cloud", str(flat), "--target", PLACE_TARGET, "--map",
                  str(d / "tiago.rmap"), "--placements", "2", "--tries", "200", "--robustness-samples", "0",
                  "--start", "-1 -1.5 0"),
        cloud=str(flat),
    )  # fmt: skip
    out["candidates"] = _cli_json(
        d / "candidates.json", "candidates", "--occupancy", str(SHARED_MAPS / "tb3_sandbox.yaml"), "--object", OBJECT,
        "--robot-pose", "-1.875 0.075 0", "--map", str(d / "tiago.rmap"), "--robustness-samples", "0",
    )  # fmt: skip
    out["navigate"] = _with_inputs(
        _cli_json(d / "navigate.json", "navigate", "--cloud", str(ramp), "--start", "-2 0.6 0", "--goal",
                  "1.7 0.6 0", "--planner", "regions"),
        cloud=str(ramp),
    )  # fmt: skip
    out["segment"] = _cli_json(d / "segment.json", "segment", str(ramp))
    smap = d / "table.smap"
    out["surface_map"] = _cli_json(
        d / "surface_map.json", "surface-map", "--robot", "tiago", "--samples", "3e5", "--height", "0.7",
        "--resolution", "0.1", "--orientations", "8", "--polygon", "0,0;1.2,0;1.2,0.6;0,0.6", "--out", str(smap),
        env=env,
    )  # fmt: skip
    out["surface_samples"] = _cli_json(
        d / "samples.json", "surface-sample", "--map", str(smap), "--n", "4", "--candidates", "5", env=env
    )
    out["point"] = _point_result(d)
    return out


def _point_result(d: Path) -> Path:
    """``point`` on a generated frame (seed 2, objects TIAGo can reach) with a grid around its table."""
    import cv2

    from baseplace.sim.pointing_scenes import generate_pointing_scene, save_pointing_scene
    from test_point_cli import REACHABLE

    files = save_pointing_scene(generate_pointing_scene(2, REACHABLE), d / "frame")
    res, side = 0.05, 80  # a 4 m grid around the table (x 0.5-1.0, y -0.5-0.5), table cells occupied
    X, Y = np.meshgrid(-1 + (np.arange(side) + 0.5) * res, -2 + (np.arange(side)[::-1] + 0.5) * res)
    cv2.imwrite(
        str(d / "table.pgm"), np.where((X >= 0.5) & (X <= 1.0) & (np.abs(Y) <= 0.5), 0, 254).astype(np.uint8)
    )
    (d / "table.yaml").write_text("image: table.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\nnegate: 0\n"
                                  "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    return _cli_json(
        d / "point.json", "point", *(x for k in ("rgb", "depth", "intrinsics", "transform", "landmarks")
                                     for x in (f"--{k}", files[k])),
        "--occupancy", str(d / "table.yaml"), "--map", str(d / "tiago.rmap"), "--robustness-samples", "0",
        "--no-motion-check",
        "--robot-pose", "-0.5 0 0",
    )  # fmt: skip


def test_every_kind_is_read_with_its_inputs(results):
    for kind, path in results.items():
        view, inputs, robot = open_view(path)
        assert view.kind == kind and robot == (None if kind == "segment" else "tiago"), kind
    place, inputs, _ = open_view(results["place"])
    obj = json.loads(results["place"].read_text())
    assert len(place.robots) == len(obj["placements"]) == 2 and len(place.paths) == 2 and len(inputs.points)
    np.testing.assert_allclose(place.robots[0].T_world_base, obj["placements"][0]["base_pose"])
    motion = place.robots[0].motion
    raw = obj["placements"][0]["motion"][0]
    assert motion is not None and motion.waypoints.shape == (len(raw["path"]) + len(raw["approach"]) - 1, 8)
    assert motion.joint_names[0] == "torso_lift_joint" and motion.pregrasp == len(raw["path"]) - 1
    cand, inputs, _ = open_view(results["candidates"])
    obj = json.loads(results["candidates"].read_text())
    assert len(cand.candidates) == len(obj["candidates"]) and len(cand.rejected) == len(obj["rejected"])
    assert inputs.grid is not None and cand.object_xyz is not None and cand.robots[0].motion is not None
    # an up vector for --transform and a --floor are applied as the command applied them
    (results["place"].parent / "up.json").write_text(
        json.dumps({**json.loads(results["place"].read_text()), "inputs": {
            "cloud": str(results["place"].parent / "flat.ply"), "transform": "0 -1 0"}, "floor": -0.5})
    )  # fmt: skip
    turned, inputs_up, _ = open_view(results["place"].parent / "up.json")
    assert turned.inputs.floor == -0.5 and turned.inputs.clouds[0][1] == "0 -1 0"
    floor = np.abs(inputs_up.points[:, 2] + 0.5) < 1e-6
    assert floor.any() and np.ptp(inputs_up.points[~floor][:, 1]) < 0.3  # the flat scene now stands upright
    point, inputs, _ = open_view(results["point"])
    obj = json.loads(results["point"].read_text())
    assert point.pointing is not None and point.pointing.selected == obj["selected"] is not None
    assert len(point.pointing.world_boxes) == len(obj["objects"]) and point.pointing.landmarks is not None
    assert inputs.image is not None and inputs.image.shape[:2] == tuple(obj["image_size"][::-1])
    assert len(point.candidates) == len(obj["candidates"]) > 0 and inputs.grid is not None
    np.testing.assert_allclose(point.object_xyz, obj["object"]["position"])
    seg, _, _ = open_view(results["segment"])
    assert len(seg.regions) == len(json.loads(results["segment"].read_text())["regions"]) >= 2
    assert len(seg.traversable) >= 1


@pytest.mark.parametrize("kind", ["place", "candidates"])
def test_drawn_motion_follows_pinocchio_forward_kinematics(results, kind):
    """The TCP path the viewer draws (yourdfpy FK of the URDF, from the JSON's base pose and joint
    waypoints) starts where pinocchio puts the TCP at the first waypoint and ends at the grasp, for
    the first robot pose and for the last one picked in the *Show* drop-down."""
    view = read_result(results[kind])
    obj = json.loads(results[kind].read_text())
    robot = Robot("tiago")
    arm = robot.arm("arm")
    server = serve(results[kind], port=0, block=False)
    try:
        layers = server.baseplace_layers
        for i in (0, len(view.robots) - 1):
            layers["robot_layer"].show(i)
            T_world_base = view.robots[i].T_world_base
            np.testing.assert_allclose(layers["robot_pose"], T_world_base, atol=1e-9)
            motion = view.robots[i].motion
            assert motion is not None and tuple(arm.joint_names) == motion.joint_names
            tcp = layers["tcp_points"]
            for q_arm, drawn in ((motion.waypoints[0], tcp[0]), (motion.waypoints[-1], tcp[-1])):
                q = arm.to_pinocchio(q_arm, robot.q_reference)
                T = T_world_base @ robot.frame_pose(q, arm.tcp_frame, relative_to=robot.spec.base_frame)
                np.testing.assert_allclose(drawn, T[:3, 3], atol=1e-6)
            if kind == "place":  # the motion ends on the target
                assert np.linalg.norm(tcp[-1] - parse_pose6(PLACE_TARGET)[:3, 3]) < 0.01
            else:  # ... on the grasp it verified
                assert np.linalg.norm(tcp[-1] - np.array(obj["candidates"][i]["grasp"])[:3, 3]) < 0.01
            # the pre-grasp copy stands back along the approach, before the straight part begins
            assert len(layers["ghosts"]) == 2 and np.linalg.norm(tcp[motion.pregrasp * 8] - tcp[-1]) > 0.02
            # the slider moves the drawn robot along the motion: at step 0 its TCP is at the start
            shown = layers["robot_layer"]
            shown._step(0)
            urdf = shown.model.urdf
            T_tcp = shown.model.T_world_root(T_world_base) @ urdf.get_transform(arm.tcp_frame, urdf.base_link)
            np.testing.assert_allclose(T_tcp[:3, 3], tcp[0], atol=1e-6)
            assert np.linalg.norm(tcp[0] - tcp[-1]) > 0.05
    finally:
        server.stop()
    assert len(view.robots) >= 2


def _hue_shares(png: Path) -> tuple[float, dict[str, float]]:
    """Share of the 3D area (panels and notification left out) that is not background, and of each hue family."""
    rgb = Image.open(png).convert("RGB")
    area = np.asarray(rgb).astype(np.int16)[170:, :930]
    covered = 1.0 - float((np.abs(area - 255).max(axis=2) <= 6).mean())
    hsv = np.asarray(rgb.convert("HSV")).astype(np.int16)[170:, :930]
    hue, coloured = hsv[..., 0] * (360 / 255), hsv[..., 1] >= 60
    families = {"red": (-1, 10), "orange": (15, 45), "yellow": (45, 60), "green": (90, 150), "blue": (190, 240), "violet": (250, 285),
                "magenta": (290, 330)}  # fmt: skip
    return covered, {k: float((coloured & (hue > a) & (hue < b)).mean()) for k, (a, b) in families.items()}


# What each kind's screenshot must show, as the least share of the 3D area of a hue family:
# path orange, candidates and traversable borders green, rejected red, the TCP's path magenta, pointed-at object yellow,
# working surface violet, regions (tab20, first blue) and the heat map (viridis) blue.
EXPECTED = {
    "place": {"orange": 0.001, "magenta": 0.0005, "blue": 0.05},
    "candidates": {
        "green": 0.001,
        "red": 0.001,
        "orange": 0.0005,
    },  # its short TCP path hides behind the robot
    "navigate": {"orange": 0.001, "blue": 0.05},
    "segment": {"green": 0.0005, "blue": 0.05},
    "surface_map": {"violet": 0.01},
    "surface_samples": {"violet": 0.01, "green": 0.0005},
    # the pointed-at object gold, the other objects and the candidates green, the finger's ray blue
    "point": {"yellow": 0.0005, "green": 0.001, "blue": 0.0005},
}


# Without a cloud (surface maps) most of the view is background.
LEAST_COVERED = {"surface_map": 0.05, "surface_samples": 0.05}
# place, candidates and point (the issues' must-show) run by default, the other kinds with the slow tests.
KINDS = [
    k if k in ("place", "candidates", "point") else pytest.param(k, marks=pytest.mark.slow) for k in EXPECTED
]


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_renders_in_headless_chromium(results, kind, tmp_path):
    browser = chromium()
    port = free_port()
    server = serve(results[kind], port=port, block=False)
    png = tmp_path / f"view-{kind}.png"
    least = LEAST_COVERED.get(kind, 0.3)

    def shortfall(shot: Path) -> tuple[float, dict[str, float], dict[str, float]]:
        """(covered, hue shares, the hue families below their least share)"""
        covered, shares = _hue_shares(shot)
        return covered, shares, {k: v for k, v in EXPECTED[kind].items() if shares[k] < v}

    def complete(shot: Path) -> bool:
        covered, _, missing = shortfall(shot)
        return covered > least and not missing

    try:
        _, _, waited = shoot_until(browser, tmp_path, f"http://127.0.0.1:{port}/", png, complete)
    finally:
        server.stop()
    covered, shares, missing = shortfall(png)
    print(
        f"{kind}: {waited:.1f} s, {covered:.0%} covered, "
        + ", ".join(f"{k} {v:.2%}" for k, v in shares.items())
    )
    shots = os.environ.get("BASEPLACE_VIEWER_SCREENSHOTS")
    if shots:
        shutil.copyfile(png, Path(shots) / png.name)
    assert covered > least, f"the 3D view is mostly blank ({covered:.0%}); see {png}"
    assert not missing, f"{kind}: too little of {missing} ({shares}); see {png}"


def test_bad_results_and_missing_inputs_are_one_line_errors(results, tmp_path):
    def fails(obj: object, *fragments: str, name: str = "r.json") -> None:
        path = tmp_path / name
        path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
        with pytest.raises(InputError) as err:
            open_view(path)
        assert all(f in str(err.value) for f in fragments), str(err.value)
        proc = run_cli("view", str(path), "--port", "0")
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
        assert "Traceback" not in proc.stderr

    fails("{", "cannot read result")
    fails([1, 2], "not a baseplace result")
    fails({"values": [0.5]}, "not a baseplace result", "baseplace place")
    fails({"schema": "baseplace.result/1", "kind": "reach", "values": [0.5]}, "`baseplace reach` result",
          "nothing to show")  # fmt: skip
    fails({"kind": "teleport"}, "unknown result kind 'teleport'", "place, candidates")
    place = json.loads(results["place"].read_text())
    fails({**place, "inputs": {"cloud": "gone/scan.pcd"}}, "written by `baseplace place`", "cloud gone/scan.pcd",
          "does not exist", "give it to the viewer with --cloud FILE")  # fmt: skip
    fails({k: v for k, v in place.items() if k != "inputs"}, "baseplace place result", "names no cloud",
          "--cloud FILE")  # fmt: skip
    # ... which the viewer then takes on its command line, as it takes a moved file
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({k: v for k, v in place.items() if k != "inputs"}))
    cloud = place["inputs"]["cloud"]
    cloud = cloud[0] if isinstance(cloud, list) else cloud
    view, inputs, _ = open_view(bare, {"cloud": [cloud], "robot": None})
    assert view.inputs.clouds[0][0] == Path(cloud) and len(inputs.points)
    proc = run_cli("view", str(bare), "--cloud", str(tmp_path / "moved.ply"))
    assert proc.returncode == 2 and "moved.ply given to the viewer (--cloud) does not exist" in proc.stderr, (
        proc.stderr
    )
    fails({**place, "inputs": {"bag": "run.mcap", "cloud_topic": ["/head/points"]}}, "ROS recording run.mcap",
          "--cloud")  # fmt: skip
    fails({**place, "inputs": {**place["inputs"], "transform": "T_world_cam.txt"}}, "transform T_world_cam.txt",
          "--transform")  # fmt: skip
    bad = json.loads(json.dumps(place))
    bad["placements"][0]["base_pose"] = [[1, 0], [0, 1]]
    fails(bad, "placement 1 base_pose", r"shape (4, 4)")
    bad = json.loads(json.dumps(place))
    bad["placements"][0]["motion"][0]["path"] = [[0.1, 0.2]]
    fails(bad, "placement 1 motion", "shape")
    cand = json.loads(results["candidates"].read_text())
    fails({**cand, "inputs": {**cand["inputs"], "occupancy": "nowhere.yaml"}}, "`baseplace candidates`", "occupancy grid nowhere.yaml",
          "--occupancy")  # fmt: skip
    samples = json.loads(results["surface_samples"].read_text())
    fails(
        {**samples, "inputs": {**samples["inputs"], "map": "missing.smap"}},
        "`baseplace surface-sample`",
        "surface map missing.smap",
        "--map",
    )
    fails(
        {**cand, "robot": None, "inputs": {k: v for k, v in cand["inputs"].items() if k != "robot"}},
        "names no robot",
    )
    proc = run_cli("view", str(tmp_path / "nothing.json"))
    assert proc.returncode == 2 and "does not exist" in proc.stderr and "--json" in proc.stderr


def test_a_robot_file_is_read_from_the_result(results, tmp_path):
    """A robot given as a file (--robot FILE) is drawn from that file, found as written or next to the JSON."""
    spec = ROOT / "tests" / "data" / "planar3.toml"
    obj = json.loads(results["candidates"].read_text())
    (tmp_path / "planar3.toml").write_text(spec.read_text())
    (tmp_path / "r.json").write_text(
        json.dumps(
            {**obj, "robot": {"name": "planar3"}, "inputs": {**obj["inputs"], "robot": "planar3.toml"}}
        )
    )
    view = read_result(tmp_path / "r.json")
    assert view.robot == str(tmp_path / "planar3.toml")
    (tmp_path / "r.json").write_text(
        json.dumps({**obj, "inputs": {**obj["inputs"], "robot": "robots/arm.toml"}})
    )
    with pytest.raises(
        InputError, match=r"from the robot file robots/arm.toml \(--robot\), which does not exist"
    ):
        read_result(tmp_path / "r.json")


def test_navigation_path_and_robot_stand_on_the_scanned_ground(results):
    """The robot at the goal and the path are drawn on the surfaces of the generated scene (its ground truth)."""
    from test_navigation import _ramp_scene

    truth = _ramp_scene(with_object=True)
    server = serve(results["navigate"], port=0, block=False)
    try:
        layers = server.baseplace_layers
        segments = np.asarray(layers["paths"][0].points, dtype=np.float64).reshape(-1, 3)
    finally:
        server.stop()
    goal = layers["robot_pose"][:3, 3]
    assert goal[:2] == pytest.approx([1.7, 0.6], abs=1e-3)
    assert (
        goal[2] == pytest.approx(float(truth.height(goal[None, :2])[0]), abs=0.03) and goal[2] > 0.3
    )  # up the ramp
    lift = segments[:, 2] - truth.height(segments[:, :2])
    assert np.all(np.abs(lift - 0.08) < 0.04), lift.round(3)  # PATH_LIFT above the true surface everywhere


def test_the_json_of_every_command_is_valid_against_the_result_schema(results, tmp_path):
    """Every command's ``--json`` is one object the JSON Schema accepts, on success and on failure (exit 2, 3)."""
    import jsonschema

    from baseplace.jobs import result_schema

    schema = result_schema()
    written = {kind: json.loads(path.read_text()) for kind, path in results.items()}
    d = next(iter(results.values())).parent
    grid = str(SHARED_MAPS / "tb3_sandbox.yaml")
    runs = {
        "robots": ("robots",),
        "occupancy": ("occupancy", grid),
        "reach": ("reach", "--map", str(d / "tiago.rmap"), "--target", PLACE_TARGET, "--base", "0.3 0.5 0"),
        "build_map": ("build-map", "--samples", "2e5", "--out", str(tmp_path / "small.rmap")),
        "scene": ("scene", "generate", "--planes", "0", "--no-box", "--extent", "4", "--out", str(tmp_path / "s.ply")),
        "robot_check": ("robot", "check", "tiago", "--png", str(tmp_path / "tiago_check.png")),
    }  # fmt: skip
    for name, args in runs.items():
        proc = run_cli(*args, "--json")
        assert proc.returncode == 0, (name, proc.stderr)
        written[name] = json.loads(proc.stdout)
    failures = {
        "exit 2, place": (2, ("place", "--cloud", "nowhere.ply", "--target", PLACE_TARGET)),
        "exit 2, candidates": (2, ("candidates", "--occupancy", grid, "--object", "1 2")),
        "exit 2, navigate": (2, ("navigate", "--cloud", "nowhere.ply", "--start", "0 0 0", "--goal", "1 0 0")),
        "exit 2, reach": (2, ("reach", "--map", str(d / "tiago.rmap"), "--target", "1 2 3")),
        "exit 3, place": (3, ("place", "--cloud", str(d / "flat.ply"), "--target", "1.0 0.5 1.9 0 0 0", "--map",
                              str(d / "tiago.rmap"), "--tries", "20", "--robustness-samples", "0")),
    }  # fmt: skip
    for name, (code, args) in failures.items():
        proc = run_cli(*args, "--json")
        assert proc.returncode == code, (name, proc.stderr)
        obj = json.loads(proc.stdout)
        assert obj["error"] and obj["exit_code"] == code, (name, obj)
        assert proc.stderr.strip().splitlines()[-1] == f"error: {obj['error']}", (name, proc.stderr)
        written[name] = obj
    for name, obj in written.items():
        try:
            jsonschema.validate(obj, schema)
        except jsonschema.ValidationError as exc:
            raise AssertionError(f"{name}: {exc.message} at {list(exc.absolute_path)}") from None
    # the schema is strict enough to fail: a pose without its heading is rejected
    broken = json.loads(json.dumps(written["place"]))
    del broken["placements"][0]["yaw"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, schema)
