"""``baseplace point --bag``: a frame recorded as sensor_msgs/Image, CameraInfo and tf gives what its files give."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baseplace.io.bag_writer import CameraInfoRecord, ImageRecord, TfRecord, write_input_bag
from baseplace.sim.pointing_scenes import generate_pointing_scene, save_pointing_scene
from conftest import run_cli

TOPICS = ("--rgb-topic", "/head/rgb", "--depth-topic", "/head/depth", "--camera-info-topic", "/head/info")


def _write(path: Path, scene, fmt: str = "mcap", rgb_encoding: str = "rgb8", depth_m: bool = False,
           depth_size: tuple[int, int] | None = None) -> Path:  # fmt: skip
    """The frame at t = 2 s (camera posed as base_link -> camera, map -> base_link on /tf), older noise before."""
    h, w = scene.depth.shape
    depth = scene.depth.astype(np.float32) if depth_m else (
        np.where(np.isfinite(scene.depth), np.rint(scene.depth * 1000), 0).clip(0, 65535).astype(np.uint16))  # fmt: skip
    if depth_size is not None:
        depth = depth[: depth_size[1], : depth_size[0]]
    rgb = scene.rgb if rgb_encoding == "rgb8" else scene.rgb[..., ::-1]
    T_map_base = np.eye(4)
    T_map_base[:3, :3] = Rotation.from_euler("z", 0.3).as_matrix()
    T_map_base[:3, 3] = [0.4, -0.2, 0.0]
    T_base_camera = np.linalg.inv(T_map_base) @ scene.T_world_camera
    t, old = 2_000_000_000, 1_000_000_000
    blank = np.zeros_like(depth)
    images = [ImageRecord("/head/rgb", "head_camera_optical", old, np.zeros_like(rgb), rgb_encoding),
              ImageRecord("/head/depth", "head_camera_optical", old, blank, "32FC1" if depth_m else "16UC1"),
              ImageRecord("/head/rgb", "head_camera_optical", t, rgb, rgb_encoding),
              ImageRecord("/head/depth", "head_camera_optical", t + 5_000_000, depth, "32FC1" if depth_m else "16UC1")]  # fmt: skip
    infos = [CameraInfoRecord("/head/info", "head_camera_optical", t, scene.intrinsics, w, h)]
    tf = [TfRecord("base_link", "head_camera_optical", 0, T_base_camera, static=True),
          TfRecord("map", "base_link", old, T_map_base), TfRecord("map", "base_link", t + old, T_map_base)]  # fmt: skip
    write_input_bag(path, fmt, tf=tf, images=images, camera_infos=infos)
    return path


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    d = tmp_path_factory.mktemp("pointbag")
    scene = generate_pointing_scene(2)
    return d, scene, save_pointing_scene(scene, d / "files")


def _point(*args: str) -> tuple[int, dict]:
    proc = run_cli("point", "--json", *args)
    return proc.returncode, json.loads(proc.stdout)


@pytest.mark.parametrize("fmt, rgb_encoding, depth_m", [("mcap", "rgb8", False), ("ros1", "bgr8", True)])
def test_the_bag_selects_the_object_its_files_select(frame, fmt, rgb_encoding, depth_m):
    d, scene, files = frame
    code, by_files = _point(*(x for k in ("rgb", "depth", "intrinsics", "transform", "landmarks")
                               for x in (f"--{k}", files[k])))  # fmt: skip
    assert code == 0, by_files["error"]
    bag = _write(d / f"frame_{fmt}{'.bag' if fmt == 'ros1' else ''}", scene, fmt, rgb_encoding, depth_m)
    code, by_bag = _point("--bag", str(bag), *TOPICS, "--landmarks", files["landmarks"])
    assert code == 0, by_bag["error"]
    assert by_bag["selected"] == by_files["selected"] and len(by_bag["objects"]) == len(by_files["objects"])
    truth = scene.objects[scene.target]
    assert np.linalg.norm(np.array(by_bag["object"]["position"]) - truth.centre) < 0.02
    np.testing.assert_allclose(by_bag["object"]["position"], by_files["object"]["position"], atol=2e-3)
    assert by_bag["inputs"]["bag"]["rgb_topic"] == "/head/rgb"
    # the viewer reads the frame back from the recording: the image and the camera's pose it was given
    from baseplace.viz.viewer import open_view

    (d / f"{fmt}.json").write_text(json.dumps(by_bag))
    view, inputs, _ = open_view(d / f"{fmt}.json")
    assert (
        view.pointing is not None
        and view.pointing.bag == bag
        and view.pointing.selected == by_bag["selected"]
    )
    assert np.array_equal(inputs.image, scene.rgb)
    np.testing.assert_allclose(inputs.T_world_camera, scene.T_world_camera, atol=1e-9)


def test_bad_bags_and_options_are_one_line_errors(frame):
    d, scene, files = frame
    bag = _write(d / "odd.mcap", scene, depth_size=(320, 240))
    good = _write(d / "good.mcap", scene)
    for args, fragment in (
        (("--bag", str(bag), *TOPICS), "they must be aligned"),
        (("--bag", str(bag), *TOPICS[:4]), "give --camera-info-topic"),
        (("--bag", str(bag), *TOPICS, "--rgb", files["rgb"]), "drop --rgb"),
        (("--bag", str(bag), "--rgb-topic", "/head/info", *TOPICS[2:]), "expected sensor_msgs/msg/Image"),
        (
            ("--bag", str(bag), *TOPICS[:2], "--depth-topic", "/nowhere", *TOPICS[4:]),
            "has no topic '/nowhere'",
        ),
        (("--bag", str(good), *TOPICS, "--world-frame", "odom"), "odom"),
        (("--rgb", files["rgb"]), "give --rgb, --depth and --intrinsics, or --bag"),
    ):
        proc = run_cli("point", "--landmarks", files["landmarks"], *args)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and fragment in lines[0], (args, proc.stderr)


def test_an_image_message_is_checked_before_an_array_is_made(monkeypatch):
    """Declared sizes that the data does not hold, sides over the limit, and pixels over the memory cap."""
    from types import SimpleNamespace

    from baseplace.errors import InputError
    from baseplace.io.image_messages import depth_from_msg, rgb_from_msg

    def msg(width, height, step, n_bytes, encoding="rgb8"):
        return SimpleNamespace(width=width, height=height, step=step, encoding=encoding, is_bigendian=0,
                               data=np.zeros(n_bytes, dtype=np.uint8))  # fmt: skip

    for bad, fragment in (
        (msg(16384, 16384, 3 * 16384, 12), "do not hold 16384 rows"),
        (msg(20000, 1, 60000, 60000), "each side must be 1 to 16384"),
        (msg(4, 4, 8, 32), "do not hold"),  # a step shorter than a row
        (msg(4, 4, 12, 48, "yuv422"), "encoding 'yuv422' is not read"),
    ):
        with pytest.raises(InputError, match=fragment):
            rgb_from_msg(bad, "/head/rgb")
    with pytest.raises(InputError, match="encoding 'rgb8' is not read; valid: 16UC1"):
        depth_from_msg(msg(4, 4, 12, 48), "/head/depth")
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "1")
    with pytest.raises(InputError, match="BASEPLACE_MAX_MEMORY_MB"):
        rgb_from_msg(msg(640, 480, 1920, 1920 * 480), "/head/rgb")
