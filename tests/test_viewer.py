"""The 3D viewer: view data files, result parsing, and the served page rendered by headless Chromium."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

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


def run_chromium(browser: str, tmp_path: Path, name: str, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "HOME": str(tmp_path)}  # chromium writes caches and crash reports under HOME
    command = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / name}", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=150, env=env)


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
        # The page unpacks its script (a WebAssembly zstd decoder) before React mounts; that step runs
        # in real time, not Chromium's virtual time, so on a loaded machine a short budget can dump the
        # DOM before the client started. Give it longer until both markers are there.
        for budget in (3_000, 10_000, 30_000):
            dom = run_chromium(browser, tmp_path, "dom", f"--virtual-time-budget={budget}", "--dump-dom", url)
            assert dom.returncode == 0, dom.stderr[-3000:]
            if client_loaded(dom.stdout):
                break
        # The scene streams over a websocket in real time while Chromium's budget is virtual time: on
        # a loaded machine the first shot can come before every layer arrived, so give it longer.
        for budget in (8_000, 20_000, 45_000):
            t1 = time.perf_counter()
            shot = run_chromium(
                browser, tmp_path, "shot", f"--virtual-time-budget={budget}", f"--screenshot={png}", url
            )
            assert shot.returncode == 0 and png.is_file(), shot.stderr[-3000:]
            problems, stats = view_problems(png)
            print(
                f"serve {t_serve:.1f} s, screenshot ({budget} ms budget) {time.perf_counter() - t1:.1f} s: {stats}"
            )
            if not problems:
                break
    finally:
        server.stop()
    assert client_loaded(dom.stdout), dom.stdout[-3000:]
    if os.environ.get("BASEPLACE_VIEWER_SCREENSHOT"):
        shutil.copyfile(png, os.environ["BASEPLACE_VIEWER_SCREENSHOT"])
    assert not problems, f"{'; '.join(problems)} ({stats}); see {png}"
