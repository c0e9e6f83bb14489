"""The 3D viewer: view data files, result parsing, and the served page rendered by headless Chromium."""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import socket
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from baseplace.errors import InputError
from baseplace.geometry.poses import parse_pose6
from baseplace.jobs.demo import DEMO_TARGET, demo_scene
from baseplace.placement.osrm import build_osrm
from baseplace.robots.spec import load_spec
from baseplace.terrain.pipeline import terrain_from_points
from baseplace.terrain.polygons import footprint_outline
from baseplace.viz import view_data, view_scene
from baseplace.viz.view_data import ViewData, load_view_data, save_view_data, view_data_from
from baseplace.viz.viewer import serve
from conftest import free_port

ROOT = Path(__file__).resolve().parents[1]
SCREENSHOT_COPY = ROOT / "docs" / "img" / "viewer.png"
# WebGL through ANGLE on Mesa's llvmpipe (EGL, no display needed): about 3x faster than ANGLE's
# SwiftShader here, whose environment-map prefiltering alone takes ~25 s. Chromium falls back to
# SwiftShader (allowed by the last flag) where Mesa's EGL is missing.
CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--use-angle=gl-egl",
    "--ignore-gpu-blocklist",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--window-size=1280,800",
]
# The placement the test scene shows: TIAGo on the demo's platform, facing the target.
BASE_POSE = [[0.866025, 0.5, 0.0, 1.275], [-0.5, 0.866025, 0.0, 0.375], [0.0, 0.0, 1.0, 0.3], [0, 0, 0, 1]]
JOINTS = {"torso_lift_joint": 0.35, "arm_1_joint": 0.91, "arm_2_joint": 0.19, "arm_3_joint": -0.24,
          "arm_4_joint": 1.92, "arm_5_joint": -0.54, "arm_6_joint": -0.28, "arm_7_joint": -0.58}  # fmt: skip


def chromium() -> str:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    pytest.fail(
        "headless Chromium is needed to render the viewer; install the Debian `chromium` package "
        "(sudo apt-get install chromium)"
    )


def write_result(directory: Path, data: ViewData, **extra) -> Path:
    save_view_data(directory / "scene_view.npz", data)
    obj = {
        "robot": "tiago",
        "target": DEMO_TARGET,
        "placement": {"base_pose": BASE_POSE, "joints": JOINTS},
        "path": {"poses": [[-3.5, 0.0, 0.0], [-1.0, 0.2, 0.1], [1.275, 0.375, -0.5236]]},
        "view_data": "scene_view.npz",
        **extra,
    }
    path = directory / "result.json"
    path.write_text(json.dumps(obj))
    return path


@pytest.fixture(scope="module")
def scene_data(tiago, tiago_map) -> ViewData:
    """The demo's scene (floor, ramp, platform) with a real OSRM from the small session map."""
    points = demo_scene().sample_cloud(np.random.default_rng(0), spacing=0.025)
    terrain = terrain_from_points(points)
    outline = footprint_outline(tiago.spec.footprint_radius, tiago.spec.footprint_polygon)
    target = parse_pose6(DEMO_TARGET)[None]
    osrm = build_osrm(terrain.segmentation, tiago_map, target, outline, tiago_map.horizontal_reach, 12)
    assert (osrm.summed > 0).any()
    return view_data_from(terrain, osrm, points, "tiago", max_points=40_000)


def test_view_data_round_trip(scene_data, tmp_path):
    assert len(scene_data.points) == 40_000 and scene_data.points.dtype == np.float32
    assert scene_data.labels.dtype == np.int16 and scene_data.labels.max() == len(scene_data.planes) - 1
    assert scene_data.osrm.max() > 0 and np.isfinite(scene_data.heights[scene_data.labels >= 0]).all()
    path = tmp_path / "v.npz"
    save_view_data(path, scene_data)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.npz"]  # no .npz.npz, no temporary left
    back = load_view_data(path)
    assert (
        back.robot == "tiago"
        and back.origin == scene_data.origin
        and back.resolution == scene_data.resolution
    )
    for name in ("points", "labels", "heights", "planes", "osrm"):
        np.testing.assert_array_equal(getattr(back, name), getattr(scene_data, name))
    with np.load(path, allow_pickle=False) as npz:  # nothing pickled
        assert all(npz[k].dtype != object for k in npz.files)


def test_view_data_errors(scene_data, tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_view_data(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(InputError, match="cannot read view data"):
        load_view_data(bad)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(InputError, match="lacks"):
        load_view_data(tmp_path / "other.npz")
    with pytest.raises(InputError, match="directory"):
        save_view_data(tmp_path / "no" / "v.npz", scene_data)
    with pytest.raises(InputError, match="same"):
        ViewData("tiago", scene_data.points, (0.0, 0.0), 0.05, scene_data.labels, scene_data.heights,
                 scene_data.planes, scene_data.osrm[:-1])  # fmt: skip


def test_geometry_helpers(scene_data):
    # Heights follow the ramp's plane; quads of a region cell lie on its plane, lifted.
    ramp = int(np.argmax(np.abs(scene_data.planes[:, 0])))
    xy = np.array([[-1.1, 0.0], [-2.0, 0.0], [1.6, 0.0], [-4.0, 2.5], [50.0, 0.0]])
    z = view_data.height_at(scene_data, xy)
    n = scene_data.planes[ramp]
    assert z[0] == pytest.approx(-(n[3] + n[0] * -1.1) / n[2], abs=1e-9)
    assert z[1] < z[0] and z[2] == pytest.approx(0.3, abs=0.02) and abs(z[3]) < 0.02 and z[4] == 0.0
    rows, cols = np.nonzero(scene_data.labels == ramp)
    verts, faces = view_data.cell_quads(scene_data, rows[:5], cols[:5], 0.1)
    assert verts.shape == (20, 3) and faces.shape == (10, 3) and faces.max() == 19
    on_plane = -(n[3] + n[0] * verts[:, 0] + n[1] * verts[:, 1]) / n[2]
    np.testing.assert_allclose(verts[:, 2] - 0.1, on_plane, atol=1e-5)
    dense = view_scene.densify(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), 0.1)
    assert len(dense) == 11 and dense[-1, 0] == 1.0


def test_robot_meshes_and_joints():
    spec = load_spec("tiago")
    handler = view_scene._package_handler(spec)
    text = spec.urdf.read_text()
    uris = {part.split('"')[0] for part in text.split('<mesh filename="')[1:]}
    assert uris and all(Path(handler(fname=u)).is_file() for u in uris)
    cfg = view_scene.joint_configuration(spec, JOINTS, ["arm_1_joint", "head_1_joint", "wheel_left_joint"])
    assert cfg == {"arm_1_joint": 0.91, "head_1_joint": 0.0, "wheel_left_joint": 0.0}


def test_port_in_use(scene_data, tmp_path):
    path = write_result(tmp_path, scene_data)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(InputError, match=f"port {port} on 127.0.0.1 is in use"):
            serve(path, port=port, block=False)
    with pytest.raises(InputError, match="host"):
        serve(path, host="no-such-host.invalid", port=0, block=False)


def screenshot_stats(png: Path) -> tuple[float, int, dict[str, float]]:
    """In the 3D area (GUI panels left out): share of non-background pixels, distinct colours, and the
    share of pixels of each hue family the scene's layers use.

    Hue, not saturation: how pale the colours come out depends on whether the environment lighting
    had loaded when Chromium took the shot, but their hues do not."""
    rgb = Image.open(png).convert("RGB")
    area = np.asarray(rgb).astype(np.int16)[170:, :930]  # below the notification, left of the panel
    background = np.abs(area - 255).max(axis=2) <= 6
    colours = len(np.unique(area.reshape(-1, 3), axis=0))
    hsv = np.asarray(rgb.convert("HSV")).astype(np.int16)[170:, :930]
    hue, coloured = hsv[..., 0] * (360 / 255), hsv[..., 1] >= 20  # saturation >= 8 %
    families = {"orange": (15, 50), "green": (70, 160), "blue": (180, 240)}
    shares = {k: float((coloured & (hue >= a) & (hue < b)).mean()) for k, (a, b) in families.items()}
    return float(1.0 - background.mean()), colours, shares


def shoot_until(
    browser: str, tmp_path: Path, url: str, png: Path, done: Callable[[Path], bool], limit_s: float = 120.0
) -> tuple[bool, str, float]:
    """Open ``url`` in headless Chromium and screenshot it to ``png`` once a second, in real time,
    until ``done(png)`` or ``limit_s`` seconds; returns (done, the page's DOM, seconds waited).

    Real time, not ``--virtual-time-budget``: Chromium's virtual time runs ahead of work it does not
    count, such as decoding an image texture (the occupancy grid, the camera's frame), so a shot
    with any budget could come before that texture was drawn. Chromium is driven over its DevTools
    pipe (it reads commands on fd 3 and answers on fd 4, each message JSON ending in a NUL byte)."""
    to_child, from_child = os.pipe(), os.pipe()
    # the child's ends at fd 10 or above, so that neither redirection below overwrites the other
    child_in, child_out = (fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (to_child[0], from_child[1]))
    os.close(to_child[0])
    os.close(from_child[1])
    env = {**os.environ, "HOME": str(tmp_path)}  # chromium writes caches and crash reports under HOME
    command = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'cdp'}", "--remote-debugging-pipe"]
    # bash (dash takes one-digit fds only) puts the pipes at fds 3 and 4 and execs Chromium; not a
    # preexec_fn: the viewer's server threads are running, and Python code between fork and exec is
    # not safe with threads.
    at_3_and_4 = f'exec "$0" "$@" 3<&{child_in} 4>&{child_out}'
    quiet = subprocess.DEVNULL
    proc = subprocess.Popen(["bash", "-c", at_3_and_4, *command], env=env, stdin=quiet, stdout=quiet, stderr=quiet,
                            pass_fds=(child_in, child_out))  # fmt: skip
    os.close(child_in)
    os.close(child_out)
    buffer, ids = b"", iter(range(1, 1_000_000))

    def call(method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        nonlocal buffer
        n = next(ids)
        message = {"id": n, "method": method, "params": params, **({"sessionId": session} if session else {})}
        os.write(to_child[1], json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + 60
        while True:
            while b"\0" in buffer:
                raw, buffer = buffer.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == n:
                    assert "error" not in reply, f"{method}: {reply['error']}"
                    return reply["result"]
            ready, _, _ = select.select([from_child[0]], [], [], max(0.0, deadline - time.monotonic()))
            chunk = os.read(from_child[0], 1 << 20) if ready else b""
            assert chunk, f"Chromium did not answer {method}"
            buffer += chunk

    t0 = time.monotonic()
    try:
        target = call("Target.createTarget", url="about:blank")["targetId"]
        session = call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        call("Emulation.setDeviceMetricsOverride", session, width=1280, height=800, deviceScaleFactor=1,
             mobile=False)  # fmt: skip
        call("Page.navigate", session, url=url)
        finished = False
        while not finished and time.monotonic() - t0 < limit_s:
            time.sleep(1.0)
            shot = call("Page.captureScreenshot", session, format="png")
            png.write_bytes(base64.b64decode(shot["data"]))
            finished = done(png)
        dom = call(
            "Runtime.evaluate", session, expression="document.documentElement.outerHTML", returnByValue=True
        )
        return finished, str(dom["result"].get("value", "")), time.monotonic() - t0
    finally:
        try:
            call("Browser.close")  # lets Chromium end its renderer and GPU processes
            proc.wait(timeout=30)
        except (AssertionError, OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait(timeout=30)
        os.close(to_child[1])
        os.close(from_child[0])


def view_problems(png: Path) -> tuple[list[str], str]:
    """What the screenshot lacks (empty when it shows the whole scene), and its statistics."""
    covered, colours, hues = screenshot_stats(png)
    stats = f"{covered:.0%} covered, {colours} colours, " + ", ".join(f"{k} {v:.1%}" for k, v in hues.items())
    problems = []
    # The floor's cloud and regions fill most of the view; the floor region (blue), the ramp region
    # (green), and the platform region and path (orange) are all drawn.
    if covered <= 0.3:
        problems.append("the 3D view is mostly blank")
    if colours <= 1000:
        problems.append(f"the 3D view has only {colours} colours")
    least = {"blue": 0.1, "green": 0.01, "orange": 0.01}
    problems += [f"no {k} layer" for k, v in least.items() if hues[k] < v]
    return problems, stats


def client_loaded(dom: str) -> bool:
    """The viser client ran: its React root and the three.js canvas of the 3D view are in the DOM."""
    return 'id="root"' in dom and 'data-engine="three.js' in dom


def test_viewer_renders_in_headless_chromium(scene_data, tmp_path):
    browser = chromium()
    path = write_result(tmp_path, scene_data)
    port = free_port()
    t0 = time.perf_counter()
    server = serve(path, port=port, block=False)
    t_serve = time.perf_counter() - t0
    png = tmp_path / "viewer.png"
    try:
        assert server.get_port() == port
        url = f"http://127.0.0.1:{port}/"
        _, dom, waited = shoot_until(browser, tmp_path, url, png, lambda shot: not view_problems(shot)[0])
        problems, stats = view_problems(png)
        print(f"serve {t_serve:.1f} s, screenshot after {waited:.1f} s: {stats}")
    finally:
        server.stop()
    assert client_loaded(dom), dom[-3000:]
    if os.environ.get("BASEPLACE_VIEWER_SCREENSHOT"):
        shutil.copyfile(png, os.environ["BASEPLACE_VIEWER_SCREENSHOT"])
    assert not problems, f"{'; '.join(problems)} ({stats}); see {png}"
