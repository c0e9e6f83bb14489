"""``baseplace point``: from a generated RGB-D frame to the object and where to stand; its outcomes."""

from __future__ import annotations

import json

import cv2
import jsonschema
import numpy as np
import pytest

from baseplace.jobs import result_schema
from baseplace.sim.pointing_scenes import (
    PALETTE,
    PointingSceneSettings,
    generate_pointing_scene,
    save_pointing_scene,
)
from conftest import run_cli

REACHABLE = PointingSceneSettings(table_size=(0.5, 1.0), n_objects=(1, 2), cylinder_height=(0.15, 0.22),
                                  box_side=(0.1, 0.14))  # fmt: skip
"""Tall objects on a narrow table: TIAGo can stand beside it and reach them (seed 2's target)."""


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """A frame of seed 2 (two objects) written as the command reads it, and its truth."""
    d = tmp_path_factory.mktemp("point")
    scene = generate_pointing_scene(2)
    return save_pointing_scene(scene, d), scene


def _point(files, *extra, **replace):
    args = {k: files[k] for k in ("rgb", "depth", "intrinsics", "transform", "landmarks")} | replace
    argv = ["point", "--json"] + [x for k, v in args.items() if v is not None for x in (f"--{k}", str(v))]
    proc = run_cli(*argv, *extra)
    obj = json.loads(proc.stdout) if proc.stdout else None
    if obj is not None:
        jsonschema.validate(obj, result_schema())
    return proc, obj


def test_the_pointed_object_is_selected_and_placed_within_2_cm(frame):
    files, scene = frame
    proc, obj = _point(files)
    assert proc.returncode == 0, proc.stderr
    assert obj["kind"] == "point" and obj["gesture"]["name"] == "Point" and obj["error"] is None
    assert len(obj["objects"]) == len(scene.objects)
    truth = scene.objects[scene.target]
    assert np.linalg.norm(np.array(obj["object"]["position"]) - truth.centre) < 0.02
    assert obj["object"]["size"] == pytest.approx(truth.size.tolist(), abs=0.03)
    assert obj["ray_2d"]["hit"] == obj["selected"] and obj["candidates"] is None
    assert {"landmarks", "gesture", "objects", "selection", "total"} <= set(obj["timings_ms"])


def test_no_hand_is_exit_3_with_the_reason(frame, tmp_path):
    files, _ = frame
    (tmp_path / "none.json").write_text("[]")
    proc, obj = _point(files, landmarks=tmp_path / "none.json")
    assert proc.returncode == 3 and obj["error"] == "no hand in the image" and obj["exit_code"] == 3
    assert proc.stderr.strip() == "error: no hand in the image"


def test_an_open_hand_is_not_pointing_exit_3_and_still_lists_the_objects(frame, tmp_path):
    files, scene = frame
    marks = json.loads(open(files["landmarks"]).read())
    for mcp in (9, 13, 17):  # stretch the curled fingers along the index finger: Stop
        for k in range(1, 4):
            for axis in "xyz":
                marks[mcp + k][axis] = marks[mcp][axis] + (marks[5 + k][axis] - marks[5][axis])
    (tmp_path / "open.json").write_text(json.dumps(marks))
    proc, obj = _point(files, landmarks=tmp_path / "open.json")
    assert proc.returncode == 3 and obj["gesture"]["name"] == "Stop"
    assert "the gesture is Stop, not Point" in obj["error"] and len(obj["objects"]) == len(scene.objects)


def test_pointing_at_an_empty_table_is_exit_3(frame, tmp_path):
    files, scene = frame
    rgb = scene.rgb.reshape(-1, 3)
    on_object = ~np.isin(rgb @ [65536, 256, 1], [np.dot(c, [65536, 256, 1]) for c in PALETTE.values()])
    v, u = np.divmod(np.arange(len(rgb)), rgb.shape[0] // scene.depth.shape[0] * scene.depth.shape[1])
    rays = scene.intrinsics.pixel_rays(u, v) @ scene.T_world_camera[:3, :3].T
    top = scene.objects[0].centre[2] - scene.objects[0].size[2] / 2
    table = (top - scene.T_world_camera[2, 3]) / rays[:, 2]  # depth of the table top along each ray
    depth = cv2.imread(files["depth"], cv2.IMREAD_UNCHANGED).reshape(-1)
    depth[on_object] = np.rint(table[on_object] * 1000)  # the objects taken off the table
    cv2.imwrite(str(tmp_path / "depth.png"), depth.reshape(scene.depth.shape))
    proc, obj = _point(files, depth=tmp_path / "depth.png")
    assert proc.returncode == 3 and "meets none of the 0 objects" in obj["error"], obj["error"]


def test_no_depth_along_the_line_is_exit_3_depth_missing(frame, tmp_path):
    files, scene = frame
    depth = cv2.imread(files["depth"], cv2.IMREAD_UNCHANGED)
    truth = scene.objects[scene.target]
    hit = scene.T_world_camera
    p_cam = (truth.centre - hit[:3, 3]) @ hit[:3, :3]
    u, v = scene.intrinsics.project(p_cam[None])[0]
    depth[int(v) - 45 : int(v) + 45, int(u) - 45 : int(u) + 45] = 0  # a black, shiny object: no returns
    cv2.imwrite(str(tmp_path / "depth.png"), depth)
    tip = np.array([json.loads(open(files["landmarks"]).read())[8][a] for a in "xy"]) * [640, 480]
    if np.all(np.abs(tip - [u, v]) < 45):
        pytest.fail("the hand lies in the blanked window; choose another scene")
    proc, obj = _point(files, depth=tmp_path / "depth.png")
    assert proc.returncode == 3 and obj["error"].startswith("depth is missing on"), obj["error"]


@pytest.mark.parametrize(
    "change, fragment",
    [({"intrinsics": "250 250 159.5"}, "neither 4 numbers"), ({"intrinsics": "250 250 900 119.5"}, "outside the 640x480"),
     ({"transform": None}, "give --transform"), ({"depth": "SMALL"}, "the depth image 16x8"),
     ({"rgb": "JUNK"}, "corrupt"), ({"landmarks": "SHORT"}, "21 landmarks, got 3")],
)  # fmt: skip
def test_bad_input_is_exit_2_with_one_line(frame, tmp_path, change, fragment):
    files, _ = frame
    cv2.imwrite(str(tmp_path / "small.png"), np.ones((8, 16), np.uint16))
    (tmp_path / "junk.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    (tmp_path / "short.json").write_text(json.dumps([[0.5, 0.5, 0]] * 3))
    names = {"SMALL": tmp_path / "small.png", "JUNK": tmp_path / "junk.png", "SHORT": tmp_path / "short.json"}
    change = {k: names.get(v, v) if isinstance(v, str) else v for k, v in change.items()}
    proc, obj = _point(files, **change)
    assert proc.returncode == 2 and fragment in obj["error"], obj["error"]
    assert len(proc.stderr.strip().splitlines()) == 1


def test_with_a_grid_the_candidates_to_pick_the_object_up(tmp_path):
    scene = generate_pointing_scene(2, REACHABLE)
    files = save_pointing_scene(scene, tmp_path)
    res, side = 0.05, 80  # a 4 m grid around the table (x 0.5-1.0, y -0.5-0.5), table cells occupied
    x = -1 + (np.arange(side) + 0.5) * res
    y = -2 + (np.arange(side)[::-1] + 0.5) * res
    X, Y = np.meshgrid(x, y)
    img = np.where((X >= 0.5) & (X <= 1.0) & (np.abs(Y) <= 0.5), 0, 254).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "grid.pgm"), img)
    (tmp_path / "grid.yaml").write_text("image: grid.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    # the map goes to --out, not the cache; the user's cache holds the compiled TIAGo kernels it reuses
    assert (
        run_cli("build-map", "--samples", "2e6", "--seed", "4", "--out", str(tmp_path / "t.rmap")).returncode
        == 0
    )
    proc, obj = _point(files, "--occupancy", str(tmp_path / "grid.yaml"), "--map", str(tmp_path / "t.rmap"),
                       "--robustness-samples", "0", "--no-motion-check", "--robot-pose", "-0.5 0 0")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    truth = scene.objects[scene.target]
    assert np.linalg.norm(np.array(obj["object"]["position"]) - truth.centre) < 0.02
    assert obj["candidates"] and obj["robot"]["name"] == "tiago"
    for c in obj["candidates"]:  # each faces the object from within the arm's reach, off the table
        d = np.hypot(c["x"] - truth.centre[0], c["y"] - truth.centre[1])
        assert 0.4 < d < 1.0 and not (0.5 <= c["x"] <= 1.0 and abs(c["y"]) <= 0.5)
    assert obj["path"] is not None
    assert obj["motion_failures"] == {}  # the field is there; with no motion check nothing is refused for it
    proc, obj = _point(files, "--occupancy", str(tmp_path / "grid.yaml"), "--map", str(tmp_path / "t.rmap"),
                       "--robustness-samples", "0", "--no-motion-check", "--png", str(tmp_path / "point.png"))  # fmt: skip
    picture = cv2.imread(obj["outputs"]["png"])
    assert proc.returncode == 0 and picture.shape[1] > picture.shape[0] * 2  # the image and the top view


def test_a_picture_on_exit_3_and_none_on_bad_input(frame, tmp_path):
    files, _ = frame
    (tmp_path / "none.json").write_text("[]")
    proc, obj = _point(files, "--png", str(tmp_path / "a.png"), landmarks=tmp_path / "none.json")
    assert proc.returncode == 3 and cv2.imread(obj["outputs"]["png"]) is not None
    proc, _ = _point(files, "--png", str(tmp_path / "b.png"), intrinsics="1 2 3")
    assert proc.returncode == 2 and not (tmp_path / "b.png").exists()
    proc, obj = _point(files, "--png", str(tmp_path / "c.txt"))
    assert proc.returncode == 2 and "--png" in obj["error"] and not (tmp_path / "c.txt").exists()


def test_the_nearest_rule_selects_the_same_object_on_a_clear_scene(frame):
    files, _ = frame
    first, nearest = _point(files)[1], _point(files, "--selection", "nearest")[1]
    assert nearest["exit_code"] == 0 and nearest["inputs"]["selection"] == "nearest"
    assert nearest["object"] == first["object"]


def test_without_landmarks_and_without_mediapipe_the_error_names_what_to_do(frame, monkeypatch):
    import sys

    for name in (
        "mediapipe",
        "mediapipe.python",
        "mediapipe.python.solutions",
        "mediapipe.python.solutions.hands",
    ):
        monkeypatch.setitem(sys.modules, name, None)  # as on an install without MediaPipe (imported or not)
    files, _ = frame
    proc, obj = _point(files, landmarks=None)
    assert (
        proc.returncode == 2 and "needs MediaPipe 0.10.21" in obj["error"] and "--landmarks" in obj["error"]
    )
    assert len(proc.stderr.strip().splitlines()) == 1
