"""``baseplace serve`` (issue 18): answers checked by pinocchio FK, errors as the CLI's lines.

In process (FastAPI's TestClient) and, for disconnects and the Python client, a real uvicorn on
a free loopback port. Oracles: pinocchio FK of the returned joints at the returned base pose
reaches the grasp; the CLI's own error line for the same bad input.
"""

from __future__ import annotations

import dataclasses
import io
import json
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from fastapi.testclient import TestClient

from baseplace.errors import InputError
from baseplace.reachability.storage import save_map
from baseplace.serve.client import Client
from baseplace.serve.server import create_app
from baseplace.serve.state import ServeSettings, ServiceState
from conftest import free_port, run_cli
from test_grasped_object import THROUGH_B, A, B, cloud, tray_scene
from test_placement import pinocchio_tcp

TARGET = " ".join(str(v) for v in (-0.05 + 0.151, 0.0, 0.70, 0.0, 0.0, np.pi))  # THROUGH_B as text


def npy_bytes(points: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, points, allow_pickle=False)
    return buf.getvalue()


UP = {"content-type": "application/octet-stream"}  # an upload's content type (others get 415)


def make_app(tiago, tiago_map, **settings):
    # settings the landed code lacks are left out, so that the same tests run against it (issue 28)
    known = {f.name for f in dataclasses.fields(ServeSettings)}
    given = {"allow_hosts": ("testserver",), **settings}
    s = ServeSettings(warm_up=False, **{k: v for k, v in given.items() if k in known})
    state = ServiceState(s)
    state.use_map(tiago, tiago_map)
    return create_app(s, state)


@pytest.fixture(scope="module")
def tray_points():
    return cloud(tray_scene(A))


@pytest.fixture(scope="module")
def client(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map, max_request_bytes=8 * 1024 * 1024)) as c:
        yield c


@pytest.fixture(scope="module")
def scene_id(client, tray_points):
    r = client.post("/scenes", params={"format": "npy"}, content=npy_bytes(tray_points), headers=UP)
    assert r.status_code == 200, r.text
    assert r.json()["points"] == len(tray_points) and r.json()["regions"] >= 1
    return r.json()["scene_id"]


def test_place_returns_placements_that_reach_the_grasp(client, scene_id, tiago, tiago_map):
    for seed in (0, 1):
        r = client.post("/place", json={"scene_id": scene_id, "targets": [TARGET], "tries": 60, "seed": seed,
                                        "placements": 2})  # fmt: skip
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["placements"], out["failures"]
        assert out["object"]["allowed"] is not None  # the bottle, found at the grasp point
        arm = tiago.arm(tiago_map.info.arm)
        for p in out["placements"]:
            T_world_base = np.array(p["base_pose"])
            q = np.array([p["joints"][0][name] for name in arm.joint_names])
            T = pinocchio_tcp(tiago, arm, q, T_world_base)  # oracle: pinocchio FK of the returned joints
            assert np.allclose(T[:3, 3], THROUGH_B[:3, 3], atol=0.01)
            assert np.allclose(T[:3, :3], THROUGH_B[:3, :3], atol=0.02)
    # the CLI's keys, with the same values where the inputs are the same
    assert {"robot", "strategy", "seed", "targets", "placements", "tries", "failures", "collisions", "object",
            "timings_ms", "regions"} <= set(out)  # fmt: skip


def test_bad_input_gets_the_clis_one_line_and_the_server_keeps_answering(
    client, scene_id, tmp_path, tray_points
):
    bad = "0.1 0 0.7 0 0"
    r = client.post("/place", json={"scene_id": scene_id, "targets": [bad]})
    assert r.status_code == 400
    np.save(tmp_path / "c.npy", tray_points)
    cli = run_cli("place", "--cloud", str(tmp_path / "c.npy"), "--target", bad)
    assert cli.returncode == 2
    assert r.json()["error"] == cli.stderr.strip().removeprefix("error: ")  # the CLI's message, word for word
    cases = [
        (
            {"scene_id": scene_id, "targets": [TARGET], "robot": "r2d2"},
            400,
            "unknown robot 'r2d2'; valid: tiago",
        ),
        ({"scene_id": "0123456789abcdef", "targets": [TARGET]}, 404, "unknown scene id"),
        ({"scene_id": scene_id, "targets": [TARGET], "strategy": "XX"}, 422, "strategy"),
        ({"scene_id": scene_id, "targets": [TARGET], "tries": 0}, 422, "tries"),
        ({"scene_id": scene_id, "targets": [TARGET], "typo": 1}, 422, "typo"),
        ({"scene_id": scene_id}, 422, "targets"),
    ]
    for body, status, words in cases:
        r = client.post("/place", json=body)
        assert r.status_code == status, (body, r.text)
        line = r.json()["error"]
        assert words in line and "\n" not in line and "Traceback" not in line
    r = client.post("/place", content=b'{"scene_id": ', headers={"content-type": "application/json"})
    assert r.status_code == 422 and "\n" not in r.json()["error"]
    assert r.json()["error"].startswith("the request body is not valid JSON at character "), r.json()["error"]
    for data, fmt, status in [(b"", "npy", 400), (b"not a cloud", "npy", 400), (b"x", "stl", 422)]:
        r = client.post("/scenes", params={"format": fmt}, content=data, headers=UP)
        assert r.status_code == status and "\n" not in r.json()["error"], r.text
    assert client.get("/health").json()["status"] == "ok"
    r = client.post("/reach", json={"targets": [TARGET], "bases": ["0 0 0"]})
    assert r.status_code == 200 and len(r.json()["values"]) == 1


def test_nothing_found_is_200_with_found_false_and_the_clis_line(client, tiago_map, tmp_path):
    # the hand passes through bottle B to grasp A: no placement (test_grasped_object); the same
    # inputs through the CLI give exit 3 and the same line
    points = cloud(tray_scene(A, B))
    r = client.post("/scenes", params={"format": "npy"}, content=npy_bytes(points), headers=UP)
    scene = r.json()["scene_id"]
    r = client.post("/place", json={"scene_id": scene, "targets": [TARGET], "tries": 30})
    assert r.status_code == 200
    out = r.json()
    assert out["found"] is False and out["placements"] == [] and out["failures"]["collision"] > 0
    map_file, cloud_file = tmp_path / "tiago.rmap", tmp_path / "two.npy"
    save_map(tiago_map, map_file)
    np.save(cloud_file, points)
    cli = run_cli(
        "place", "--cloud", str(cloud_file), "--map", str(map_file), "--target", TARGET, "--tries", "30"
    )
    assert cli.returncode == 3
    assert out["error"] == cli.stderr.strip().removeprefix("error: ")


def test_oversized_requests_get_413_and_the_server_keeps_answering(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map, max_request_bytes=4096)) as c:
        r = c.post("/scenes", params={"format": "npy"}, content=b"\0" * 10_000, headers=UP)
        assert r.status_code == 413 and "over the limit of 4096 bytes" in r.json()["error"]

        def chunks():  # no content-length: counted while it streams
            for _ in range(10):
                yield b"\0" * 1000

        r = c.post("/scenes", params={"format": "npy"}, content=chunks(), headers=UP)
        assert r.status_code == 413, r.text
        assert c.get("/health").status_code == 200


def test_the_public_names_resolve():
    import baseplace.serve

    for name in baseplace.serve.__all__:
        assert getattr(baseplace.serve, name) is not None, name


def test_health_openapi_and_docs(client):
    h = client.get("/health").json()
    assert h["status"] == "ok" and h["rss_mb"] > 0
    doc = client.get("/openapi.json").json()
    for path in ("/place", "/candidates", "/reach", "/navigate", "/surface-map", "/surface-samples", "/scenes",
                 "/scenes/{scene_id}/segmentation", "/health"):  # fmt: skip
        assert path in doc["paths"], path
    assert "targets" in doc["components"]["schemas"]["PlaceRequest"]["properties"]
    assert client.get("/docs").status_code == 200


@pytest.fixture(scope="module")
def server(tiago, tiago_map):
    import uvicorn

    port = free_port()
    app = make_app(tiago, tiago_map, timeout_s=20.0)
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", lifespan="on"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not srv.started and time.time() < deadline:
        time.sleep(0.05)
    assert srv.started
    yield f"http://127.0.0.1:{port}", port
    srv.should_exit = True  # graceful: requests in flight finish, then the lifespan ends
    thread.join(timeout=30)
    assert not thread.is_alive()


def test_a_client_that_disconnects_mid_request_is_dropped(server, tray_points):
    url, port = server
    body = npy_bytes(tray_points)
    # half an upload, then gone
    with socket.create_connection(("127.0.0.1", port)) as s:
        s.sendall(b"POST /scenes?format=npy HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
                  + f"Content-Length: {len(body)}\r\n\r\n".encode() + body[: len(body) // 2])  # fmt: skip
    # a whole place request, gone before the answer
    with Client(url) as c:
        scene = c.upload_scene(body, "npy")
        request = json.dumps({"scene_id": scene, "targets": [TARGET], "tries": 60}).encode()
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.sendall(b"POST /place HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                      + f"Content-Length: {len(request)}\r\n\r\n".encode() + request)  # fmt: skip
        # the server keeps answering, the scene still there
        assert c.health()["status"] == "ok"
        out = c.place(scene, [TARGET], tries=60)
        assert out["placements"]
        assert (
            c.reach([TARGET], [f"{out['placements'][0]['x']} {out['placements'][0]['y']} 0"])["values"][0]
            >= 0
        )
        with pytest.raises(InputError, match="unknown scene id"):
            c.place("ffffffffffffffff", [TARGET])
        with pytest.raises(InputError, match="needs 6 numbers"):
            c.place(scene, ["1 2 3"])


def test_a_request_over_the_time_limit_gets_504_and_the_next_one_an_answer(tiago, tiago_map, tray_points):
    with TestClient(make_app(tiago, tiago_map, timeout_s=0.001)) as c:
        r = c.post("/scenes", params={"format": "npy"}, content=npy_bytes(tray_points), headers=UP)
        assert r.status_code == 504 and "longer than" in r.json()["error"]
        assert c.get("/health").status_code == 200


def test_a_grid_is_read_as_map_server_reads_it_and_a_bad_one_keeps_the_last(client, scene_id, tmp_path):
    import cv2

    from baseplace.world.occupancy import load_occupancy

    image = np.full((40, 60), 254, np.uint8)
    image[:10, :20] = 0  # first image row: the top of the map (max y)
    ok, png = cv2.imencode(".png", image)
    assert ok
    params = {"resolution": 0.1, "format": "png", "origin_x": -3.0, "origin_y": -2.0}
    r = client.post(f"/scenes/{scene_id}/grid", params=params, content=png.tobytes(), headers=UP)
    assert r.status_code == 200, r.text
    # oracle: the same image and YAML read from files by the loader the CLI uses
    (tmp_path / "m.png").write_bytes(png.tobytes())
    (tmp_path / "m.yaml").write_text("image: m.png\nresolution: 0.1\norigin: [-3.0, -2.0, 0.0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    assert r.json()["data"] == load_occupancy(tmp_path / "m.yaml").to_json()["data"]
    bad = client.post(f"/scenes/{scene_id}/grid", params=params, content=b"not an image", headers=UP)
    assert bad.status_code == 400 and "cannot read map image" in bad.json()["error"]
    assert bad.json()["error"].startswith(scene_id + "/")  # the scene's file, no path of the server
    again = client.post(f"/scenes/{scene_id}/grid", params=params, content=png.tobytes(), headers=UP)
    assert again.json()["data"] == r.json()["data"]


def test_a_ros_recording_is_a_scene_with_its_cloud_and_grid(client, tmp_path):
    from baseplace.io.bag import read_bag
    from test_io_bag import _write

    bag = tmp_path / "rec.bag"
    _write(bag, "ros1")  # the mug cloud on a moving base, tf, and the depot map
    params = {"format": "bag", "cloud_topic": "/head/points", "map_topic": "/map"}
    r = client.post("/scenes", params=params, content=bag.read_bytes(), headers=UP)
    assert r.status_code == 200, r.text
    out = r.json()
    # oracle: the recording read from the file by the CLI's reader
    truth = read_bag(bag, ["/head/points"], "/map")
    assert out["points"] == len(truth.world_points()) and out["grid"] is True
    from baseplace.world.occupancy import load_occupancy

    held = load_occupancy(client.app.state.service.scene(out["scene_id"]).grid_yaml)  # as the CLI reads it
    assert np.array_equal(held.data, truth.grid.data) and held.resolution == truth.grid.resolution
    assert np.allclose(held.origin, truth.grid.origin)
    seg = client.get(f"/scenes/{out['scene_id']}/segmentation").json()
    assert seg["cloud"]["points"] == len(truth.world_points())
    again = client.post(
        f"/scenes/{out['scene_id']}/grid", params={"resolution": 0.05}, content=b"", headers=UP
    )
    assert again.status_code == 400  # an empty grid upload, and the recording's grid stays
    r = client.post("/scenes", params={"format": "bag"}, content=bag.read_bytes(), headers=UP)
    assert r.status_code == 400 and "cloud topic" in r.json()["error"]
    r = client.post(
        "/scenes", params={**params, "cloud_topic": "/nope"}, content=bag.read_bytes(), headers=UP
    )
    assert r.status_code == 400 and "/nope" in r.json()["error"] and "\n" not in r.json()["error"]


def _valid(obj: dict) -> dict:
    """``obj`` checked against the one result schema (the CLI's ``--json`` contract)."""
    import jsonschema

    from baseplace.jobs import result_schema

    jsonschema.validate(obj, result_schema())
    return obj


def test_every_job_endpoint_answers_the_clis_report_on_success_and_failure(
    client, scene_id, tiago_map, tmp_path
):
    """Each endpoint's answer, found, nothing found and bad input, is a valid ``baseplace.result/1``
    report of its kind; where the inputs are the CLI's, the values and the error lines are the CLI's."""
    import cv2

    from test_navigation import _ramp_scene

    def post(path: str, body: dict, status: int, kind: str, exit_code: int) -> dict:
        r = client.post(path, json=body)
        assert r.status_code == status, (path, body, r.text)
        out = _valid(r.json())
        assert out["kind"] == kind and out["exit_code"] == exit_code, out
        assert (out["error"] is None) == (exit_code == 0)
        if exit_code:
            assert "\n" not in out["error"] and "Traceback" not in out["error"]
        text = json.dumps(out)  # no path of the server: its temporary folders, its Python, this checkout
        for server_path in (
            "baseplace-serve-",
            tempfile.gettempdir() + "/",
            sys.prefix,
            str(Path(__file__).parents[1]),
        ):
            assert server_path not in text, (path, server_path)
        return out

    # place: found, nothing found (tested above for its line), bad input, unknown scene, schema misfit
    out = post("/place", {"scene_id": scene_id, "targets": [TARGET], "tries": 60}, 200, "place", 0)
    assert out["placements"] and out["scene_id"] == scene_id
    post("/place", {"scene_id": scene_id, "targets": ["1 2 3"]}, 400, "place", 2)
    missing = post("/place", {"scene_id": "0123456789abcdef", "targets": [TARGET]}, 404, "place", 2)
    assert "unknown scene id" in missing["error"]
    post("/place", {"scene_id": scene_id, "targets": [TARGET], "tries": 0}, 422, "place", 2)
    # reach: the values of the map, and a base pose with two numbers
    out = post("/reach", {"targets": [TARGET], "bases": ["0 0 0", "-0.4 0 0"]}, 200, "reach", 0)
    assert len(out["values"]) == 2
    bad = post("/reach", {"targets": [TARGET], "bases": ["0 0"]}, 400, "reach", 2)
    assert "x y yaw" in bad["error"]
    # segment and grid: the scene's segmentation, the grid as map_server reads it
    seg = client.get(f"/scenes/{scene_id}/segmentation")
    assert seg.status_code == 200 and _valid(seg.json())["kind"] == "segment" and seg.json()["regions"]
    image = np.full((80, 80), 254, np.uint8)
    ok, png = cv2.imencode(".png", image)
    assert ok
    r = client.post(f"/scenes/{scene_id}/grid", params={"resolution": 0.05, "format": "png", "origin_x": -2.0,
                                                        "origin_y": -2.0}, content=png.tobytes(), headers=UP)  # fmt: skip
    assert r.status_code == 200 and _valid(r.json())["kind"] == "occupancy", r.text
    bad_grid = client.post(
        f"/scenes/{scene_id}/grid", params={"resolution": 0.05}, content=b"not an image", headers=UP
    )
    assert bad_grid.status_code == 400 and _valid(bad_grid.json())["kind"] == "occupancy"
    # candidates around the bottle, on the grid and the cloud, twice (the second on the scene's kept
    # environment): the CLI's candidates and rejects for the same files; an object with two numbers; outside
    (tmp_path / "g.png").write_bytes(png.tobytes())
    (tmp_path / "g.yaml").write_text("image: g.png\nresolution: 0.05\norigin: [-2.0, -2.0, 0.0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    np.save(tmp_path / "tray.npy", client.app.state.service.scene(scene_id).cache.points)
    save_map(tiago_map, tmp_path / "tiago.rmap")
    cli = run_cli("candidates", "--occupancy", str(tmp_path / "g.yaml"), "--cloud", str(tmp_path / "tray.npy"),
                  "--object", "0.101 0 0.6", "--map", str(tmp_path / "tiago.rmap"), "--no-motion-check",
                  "--robustness-samples", "0", "--json")  # fmt: skip
    truth = json.loads(cli.stdout)
    assert cli.returncode in (0, 3) and truth["rejected"], cli.stderr
    for _ in range(2):
        out = client.post("/candidates", json={"scene_id": scene_id, "object": "0.101 0 0.6",
                                               "no_motion_check": True, "robustness_samples": 0})  # fmt: skip
        assert out.status_code == 200, out.text
        out = _valid(out.json())
        assert out["kind"] == "candidates" and out["exit_code"] == cli.returncode
        assert (out["exit_code"] == 0) == bool(out["candidates"]) == out.get("found", True)
        for key in ("candidates", "rejected", "object", "failures"):
            assert out[key] == truth[key], key
    # found: the CLI test's sandbox grid alone (use_cloud off), with the robot's pose: its candidates and path
    from conftest import SHARED

    sandbox = SHARED / "maps" / "tb3_sandbox.yaml"
    r = client.post(f"/scenes/{scene_id}/grid", params={"resolution": 0.05, "format": "pgm", "origin_x": -10.0,
                                                        "origin_y": -10.0},
                    content=(SHARED / "maps" / "tb3_sandbox.pgm").read_bytes(), headers=UP)  # fmt: skip
    assert r.status_code == 200, r.text
    body = {"scene_id": scene_id, "object": "-1.025 -0.775 0.6", "robot_pose": "-1.875 0.075 0", "use_cloud": False,
            "no_motion_check": True, "robustness_samples": 0}  # fmt: skip
    out = post("/candidates", body, 200, "candidates", 0)
    cli = run_cli("candidates", "--occupancy", str(sandbox), "--object", body["object"], "--robot-pose",
                  body["robot_pose"], "--map", str(tmp_path / "tiago.rmap"), "--no-motion-check",
                  "--robustness-samples", "0", "--json")  # fmt: skip
    assert cli.returncode == 0, cli.stderr
    truth = json.loads(cli.stdout)
    assert out["candidates"] and out["path"] is not None
    for key in ("candidates", "rejected", "path", "robot_pose", "object"):
        assert out[key] == truth[key], key
    bad = post("/candidates", {"scene_id": scene_id, "object": "1 2"}, 400, "candidates", 2)
    outside = post("/candidates", {"scene_id": scene_id, "object": "30 0 0.6"}, 400, "candidates", 2)
    cli = run_cli(
        "candidates",
        "--occupancy",
        str(sandbox),
        "--object",
        "30 0 0.6",
        "--map",
        str(tmp_path / "tiago.rmap"),
    )
    assert cli.returncode == 2 and outside["error"] == cli.stderr.strip()[len("error: ") :]
    assert "outside the occupancy grid's bounds" in outside["error"] and "/" not in outside["error"]
    # navigate on the ramp scene: the CLI's path for the same inputs, its lines for bad ones
    ramp = _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0))
    ramp_id = client.post("/scenes", params={"format": "npy"}, content=npy_bytes(ramp), headers=UP).json()[
        "scene_id"
    ]
    np.save(tmp_path / "ramp.npy", ramp)
    nav = {"start": "-2 0.6 0", "goal": "1.7 0.6 0", "planner": "regions"}
    out = post("/navigate", {"scene_id": ramp_id, **nav}, 200, "navigate", 0)
    cli = run_cli("navigate", "--cloud", str(tmp_path / "ramp.npy"), "--start", nav["start"], "--goal", nav["goal"],
                  "--planner", "regions", "--json")  # fmt: skip
    assert cli.returncode == 0, cli.stderr
    truth = json.loads(cli.stdout)
    for key in ("poses", "length", "regions", "start", "goal", "planner", "footprint_radius"):
        assert out[key] == truth[key], key
    for start, status, code in (("0.7 0.6 0", 400, 2), ("-0.7 -1.9 0", 400, 2)):
        body = {"scene_id": ramp_id, "start": start, "goal": "1.7 0.6 0"}
        out = post("/navigate", body, status, "navigate", code)
        cli = run_cli(
            "navigate", "--cloud", str(tmp_path / "ramp.npy"), "--start", start, "--goal", "1.7 0.6 0"
        )
        assert cli.returncode == code and out["error"] == cli.stderr.strip().removeprefix("error: ")
    none = post("/navigate", {"scene_id": ramp_id, "start": "-2 -1.9 0", "goal": "0.5 -1.9 0", "time_limit": 0.3},
                200, "navigate", 3)  # fmt: skip
    assert none["found"] is False and "no path" in none["error"]
    # surface map and samples on the service's warm map; a self-crossing polygon; an unknown map id
    body = {"polygon": "0,0;1.2,0;1.2,0.6;0,0.6", "height": 0.7, "resolution": 0.1, "orientations": 8}
    out = post("/surface-map", body, 200, "surface_map", 0)
    assert out["nonzero_poses"] > 0
    bad = post("/surface-map", {**body, "polygon": "0,0;1,1;1,0;0,1"}, 400, "surface_map", 2)
    assert "not simple" in bad["error"]
    samples = post("/surface-samples", {"surface_map_id": out["surface_map_id"], "n": 3, "candidates": 5}, 200,
                   "surface_samples", 0)  # fmt: skip
    assert len(samples["poses"]) == 3 and all(p["reachability"] > 0 for p in samples["poses"])
    post("/surface-samples", {"surface_map_id": "ffffffffffffffff"}, 404, "surface_samples", 2)
    post("/surface-samples", {"surface_map_id": out["surface_map_id"], "n": 0}, 422, "surface_samples", 2)
    assert client.get("/health").json()["status"] == "ok"


def test_the_serve_commands_defaults_are_the_settings_defaults(monkeypatch):
    """``baseplace serve`` with no option serves exactly ``ServeSettings()``: one copy of every default."""
    from baseplace.cli import build_parser
    from baseplace.serve import command, server

    served: list[ServeSettings] = []
    monkeypatch.setattr(server, "serve", served.append)
    monkeypatch.delenv("BASEPLACE_TOKEN", raising=False)
    assert command.cmd_serve(build_parser("serve").parse_args(["serve"])) == 0
    assert served == [ServeSettings()]
    # and an option still reaches its field
    assert (
        command.cmd_serve(
            build_parser("serve").parse_args(["serve", "--max-inflight-mb", "300", "--robot", "pr2"])
        )
        == 0
    )
    assert served[1] == dataclasses.replace(ServeSettings(), max_inflight_bytes=300 * 2**20, robots=("pr2",))


def test_the_services_folder_is_deleted_without_close():
    """The scenes' folder goes with ``close()``, and also when a state is dropped unclosed (an app
    never started) or its process exits without closing it."""
    import gc
    import subprocess

    state = ServiceState(ServeSettings(warm_up=False, robots=()))
    folder = state.folder
    assert folder.is_dir()
    state.close(wait_s=1.0)
    assert not folder.exists()
    state = ServiceState(ServeSettings(warm_up=False, robots=()))
    folder = state.folder
    del state
    gc.collect()
    assert not folder.exists()
    code = "from baseplace.serve.state import ServeSettings, ServiceState\n" \
           "s = ServiceState(ServeSettings(warm_up=False, robots=()))\nprint(s.folder)"  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "baseplace-serve-" in proc.stdout and not Path(proc.stdout.strip()).exists()
