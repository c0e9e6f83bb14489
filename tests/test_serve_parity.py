"""The service at parity with the CLI (issue 29, item 2): the docs' examples through both.

Each case runs one of the docs' commands (README.md, docs/ros.md) through the CLI (in process,
``--json``) and the same request through the service (FastAPI's TestClient), with the same seed
and the same map, and compares the answers field by field: placements (poses within 1e-9,
joints, regions), counts, refusal reasons and error lines, the paths' ends. Oracle: the CLI.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("fastapi")

from fastapi.testclient import TestClient

from baseplace.reachability.storage import save_map
from conftest import SHARED, run_cli
from test_serve import UP, _valid, make_app

MUG = SHARED / "pointclouds" / "table_scene_mug_stereo_textured.pcd"
MUG_UP = "0.0162 -0.8378 -0.5458"  # README: the camera frame's up vector
MUG_GRASP = "0.062 0.608 -0.43 0 0 1.5708"
BAG_TARGET = "4.45 7.80 1.02 0 1.5708 0"  # docs/ros.md
SCENE_TARGET = "1.0 0.5 0.75 0 1.5708 0"  # README's place and explain


@pytest.fixture(scope="module")
def files(tmp_path_factory, tiago_map):
    """The map both sides use, the docs' recording and generated scene."""
    from test_io_bag import _write

    folder = tmp_path_factory.mktemp("parity")
    save_map(tiago_map, folder / "tiago.rmap")
    _write(folder / "rec.bag", "ros1")  # docs/ros.md: PCL's mug on a moving base, tf, the depot map
    made = run_cli("scene", "generate", "--size-class", "medium", "--planes", "4", "--seed", "3",
                   "--out", str(folder / "scene.ply"))  # fmt: skip
    assert made.returncode == 0, made.stderr
    return folder


@pytest.fixture(scope="module")
def client(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map)) as c:
        yield c


def cli(files: Path, *args: str) -> dict:
    out = run_cli(*args, "--map", str(files / "tiago.rmap"), "--json")
    assert out.returncode in (0, 3), out.stderr
    report: dict = json.loads(out.stdout)
    return report


def upload(client: TestClient, path: Path, **params: object) -> str:
    fmt = path.suffix.lstrip(".")
    r = client.post("/scenes", params={"format": fmt, **params}, content=path.read_bytes(), headers=UP)
    assert r.status_code == 200, r.text
    return str(r.json()["scene_id"])


def post(client: TestClient, path: str, body: dict) -> dict:
    r = client.post(path, json=body)
    assert r.status_code == 200, r.text
    out: dict = r.json()
    return out


def counted(fn: Callable[..., Any], calls: list[str]) -> Callable[..., Any]:
    """``fn`` that notes each call in ``calls``."""

    def call(*args: Any, **kwargs: Any) -> Any:
        calls.append(fn.__name__)
        return fn(*args, **kwargs)

    return call


def assert_same_placements(cli_out: dict, svc: dict) -> None:
    """The place answers agree: exit code, error line, failure counts, each placement and its path's ends."""
    for key in ("exit_code", "error", "failures", "targets", "strategy", "tries", "seed"):
        assert svc.get(key) == cli_out.get(key), key
    assert len(svc["placements"]) == len(cli_out["placements"])
    for mine, theirs in zip(svc["placements"], cli_out["placements"], strict=True):
        assert np.allclose(mine["base_pose"], theirs["base_pose"], rtol=0, atol=1e-9)
        for key in ("region", "reachability", "joints", "robustness", "motion"):
            assert mine.get(key) == theirs.get(key), key
        assert ("path" in mine) == ("path" in theirs)
        if "path" in theirs:
            for end in (0, -1):
                assert mine["path"]["poses"][end] == theirs["path"]["poses"][end]
            assert mine["path"]["length"] == theirs["path"]["length"]


def test_the_mug_cloud_with_its_up_vector_and_a_floor(client, files):
    """README: PCL's mug in its camera frame, ``--transform`` (up vector), ``--floor``, ``--grasp-point``."""
    truth = cli(files, "place", "--cloud", str(MUG), "--transform", MUG_UP, "--floor", "-1.25",
                "--grasp-point", MUG_GRASP, "--no-motion-check")  # fmt: skip
    assert truth["exit_code"] == 0 and truth["placements"], truth["error"]
    scene = upload(client, MUG, transform=MUG_UP, floor=-1.25)
    svc = post(client, "/place", {"scene_id": scene, "grasp_points": [MUG_GRASP], "no_motion_check": True})
    assert_same_placements(truth, svc)
    # README's next line, with the reaching-motion check: the same refusal (or the same placements)
    truth = cli(files, "place", "--cloud", str(MUG), "--transform", MUG_UP, "--floor", "-1.25",
                "--grasp-point", MUG_GRASP)  # fmt: skip
    svc = post(client, "/place", {"scene_id": scene, "grasp_points": [MUG_GRASP]})
    assert_same_placements(truth, svc)
    assert svc.get("found", True) == (truth["exit_code"] == 0)
    assert svc["collisions"] == truth["collisions"]
    # the 4x4 matrix of the same rotation, as the CLI reads it from a file: the same scene
    from baseplace.terrain.io import load_transform

    matrix = " ".join(repr(float(v)) for v in load_transform(MUG_UP).ravel())
    again = upload(client, MUG, transform=matrix, floor=-1.25)
    held = client.app.state.service
    assert np.array_equal(held.scene(again).cache.points, held.scene(scene).cache.points)
    # no up vector: the CLI's refusal of a camera-frame cloud, word for word
    refused = run_cli("segment", str(MUG))
    r = client.post("/scenes", params={"format": "pcd"}, content=MUG.read_bytes(), headers=UP)
    assert refused.returncode == 2 and r.status_code == 400
    assert r.json()["error"] == refused.stderr.strip().removeprefix("error: ")


def test_the_recording_with_its_grid(client, files):
    """docs/ros.md: the recording's cloud and its map topic's grid; 2 placements in the CLI and the service."""
    truth = cli(files, "place", "--bag", str(files / "rec.bag"), "--cloud-topic", "/head/points",
                "--map-topic", "/map", "--world-frame", "map", "--target", BAG_TARGET, "--placements", "2")  # fmt: skip
    assert truth["exit_code"] == 0 and len(truth["placements"]) == 2, truth["error"]
    scene = upload(client, files / "rec.bag", cloud_topic="/head/points", map_topic="/map", world_frame="map")
    svc = post(client, "/place", {"scene_id": scene, "targets": [BAG_TARGET], "placements": 2})
    assert_same_placements(truth, svc)
    # with a start on the grid: each placement's path on the navigation map
    start = "3.0 8.5 0"
    truth = cli(files, "place", "--bag", str(files / "rec.bag"), "--cloud-topic", "/head/points",
                "--map-topic", "/map", "--target", BAG_TARGET, "--placements", "2", "--start", start,
                "--no-motion-check", "--robustness-samples", "0")  # fmt: skip
    assert truth["exit_code"] == 0 and truth["placements"][0]["path"], truth["error"]
    svc = post(client, "/place", {"scene_id": scene, "targets": [BAG_TARGET], "placements": 2, "start": start,
                                  "no_motion_check": True, "robustness_samples": 0})  # fmt: skip
    assert_same_placements(truth, svc)
    # the grid left out: the cloud alone, as the CLI without --map-topic (no floor in it: refused alike)
    refused = run_cli("place", "--bag", str(files / "rec.bag"), "--cloud-topic", "/head/points",
                      "--target", BAG_TARGET, "--map", str(files / "tiago.rmap"))  # fmt: skip
    r = client.post("/place", json={"scene_id": scene, "targets": [BAG_TARGET], "use_grid": False})
    assert refused.returncode == 2 and r.status_code == 400
    assert r.json()["error"] == refused.stderr.strip().removeprefix("error: ")


def test_the_recording_fused(client, files):
    """README: ``--bag ... --bag-clouds all --fuse``: every cloud message fused into one OctoMap."""
    truth = cli(files, "place", "--bag", str(files / "rec.bag"), "--cloud-topic", "/head/points",
                "--map-topic", "/map", "--bag-clouds", "all", "--fuse", "--fuse-miss", "0.3",
                "--target", BAG_TARGET, "--no-motion-check", "--robustness-samples", "0")  # fmt: skip
    assert truth["exit_code"] == 0, truth["error"]
    scene = upload(client, files / "rec.bag", cloud_topic="/head/points", map_topic="/map", bag_clouds="all",
                   fuse=True, fuse_miss=0.3)  # fmt: skip
    svc = post(client, "/place", {"scene_id": scene, "targets": [BAG_TARGET], "no_motion_check": True,
                                  "robustness_samples": 0})  # fmt: skip
    assert_same_placements(truth, svc)
    assert svc["object"] == truth["object"]


def test_a_place_with_start_gets_the_same_path(client, files):
    """README: ``place --cloud scene.ply --target ... --start "-3 -3 0"``: placements and their paths."""
    truth = cli(files, "place", "--cloud", str(files / "scene.ply"), "--target", SCENE_TARGET,
                "--start", "-3 -3 0")  # fmt: skip
    assert truth["exit_code"] == 0 and truth["placements"][0]["path"], truth["error"]
    scene = upload(client, files / "scene.ply")
    svc = post(client, "/place", {"scene_id": scene, "targets": [SCENE_TARGET], "start": "-3 -3 0"})
    assert_same_placements(truth, svc)
    assert svc["placements"][0]["path"]["poses"][0] == [-3.0, -3.0, 0.0]
    # in degrees: the same answer (--degrees)
    deg = "1.0 0.5 0.75 0 90.0 0"
    truth = cli(files, "place", "--cloud", str(files / "scene.ply"), "--target", deg, "--degrees",
                "--no-motion-check", "--robustness-samples", "0")  # fmt: skip
    svc = post(client, "/place", {"scene_id": scene, "targets": [deg], "degrees": True, "no_motion_check": True,
                                  "robustness_samples": 0})  # fmt: skip
    assert truth["exit_code"] == 0
    assert_same_placements(truth, svc)


def test_a_start_on_a_scene_reuses_its_segmentation(client, files, monkeypatch):
    """The navigation map of ``start`` comes from the scene's kept segmentation, not a new one per request."""
    import baseplace.terrain.pipeline

    scene = upload(client, files / "scene.ply")
    made: list[str] = []
    real = baseplace.terrain.pipeline.terrain_from_points
    monkeypatch.setattr(baseplace.terrain.pipeline, "terrain_from_points", counted(real, made))
    out = post(client, "/place", {"scene_id": scene, "targets": [SCENE_TARGET], "start": "-3 -3 0",
                                  "no_motion_check": True, "robustness_samples": 0})  # fmt: skip
    assert out["placements"][0]["path"] and made == []


def test_navigate_in_degrees_as_the_cli(client, files):
    """README: ``navigate --cloud scene.ply --start "-3 -3 0" --goal ...``, the goal's heading in degrees."""
    args = ("--start", "-3 -3 0", "--goal", "0.5 1.4 90", "--degrees")
    truth = run_cli("navigate", "--cloud", str(files / "scene.ply"), *args, "--planner", "regions", "--json")
    assert truth.returncode == 0, truth.stderr
    truth = json.loads(truth.stdout)
    scene = upload(client, files / "scene.ply")
    svc = post(client, "/navigate", {"scene_id": scene, "start": "-3 -3 0", "goal": "0.5 1.4 90",
                                     "degrees": True, "planner": "regions"})  # fmt: skip
    for key in ("exit_code", "poses", "length", "regions", "start", "goal", "planner"):
        assert svc[key] == truth[key], key
    assert svc["goal"]["yaw"] == pytest.approx(np.pi / 2, abs=1e-4)


@pytest.mark.parametrize(
    "body, args",
    [
        ({"targets": ["1.0 0.5 0.75 0 90 0"]}, ("--target", "1.0 0.5 0.75 0 90 0")),  # degrees, no flag
        ({"targets": ["1000 500 750 0 1.5708 0"]}, ("--target", "1000 500 750 0 1.5708 0")),  # millimetres
        ({"targets": ["1.0 0.5 3.75 0 1.5708 0"]}, ("--target", "1.0 0.5 3.75 0 1.5708 0")),  # above reach
        (
            {"targets": [SCENE_TARGET], "start": "-3 -3 180"},
            ("--target", SCENE_TARGET, "--start", "-3 -3 180"),
        ),
        ({"targets": [SCENE_TARGET], "start": "40 0 0"}, ("--target", SCENE_TARGET, "--start", "40 0 0")),
        (
            {"targets": [SCENE_TARGET], "robustness_motion": True, "no_motion_check": True},
            ("--target", SCENE_TARGET, "--robustness-motion", "--no-motion-check"),
        ),  # a robustness with the motion needs the motion check
    ],
)
def test_input_checks_refuse_as_the_cli_does(client, files, body, args):
    """Issue 29 item 1's checks: 400 with the CLI's one line (exit 2), before any search."""
    scene = client.app.state.service
    ids = [i for i in scene.scene_ids() if scene.scene(i).source == "upload.ply"]
    scene_id = ids[-1] if ids else upload(client, files / "scene.ply")
    refused = run_cli("place", "--cloud", str(files / "scene.ply"), *args, "--map", str(files / "tiago.rmap"))
    assert refused.returncode == 2, refused.stderr
    r = client.post("/place", json={"scene_id": scene_id, **body})
    assert r.status_code == 400, r.text
    assert r.json()["error"] == refused.stderr.strip().removeprefix("error: ")


@pytest.mark.parametrize(
    "body, args",
    [
        ({"base": "0.2 0.6 60"}, ("--base", "0.2 0.6 60")),  # a heading in degrees, no flag
        ({"base": "0.2 0.6 1.05", "grasp_point": SCENE_TARGET}, ("--base", "0.2 0.6 1.05", "--grasp-point",
                                                                 SCENE_TARGET)),  # both target and grasp point
    ],
)  # fmt: skip
def test_explain_refuses_as_the_cli_does(client, files, body, args):
    refused = run_cli("explain", "--target", SCENE_TARGET, *args, "--map", str(files / "tiago.rmap"))
    assert refused.returncode == 2, refused.stderr
    r = client.post("/explain", json={"target": SCENE_TARGET, **body})
    assert r.status_code == 400 and _valid(r.json())["kind"] == "explain"
    assert r.json()["error"] == refused.stderr.strip().removeprefix("error: ")


def test_explain_answers_as_the_cli(client, files, monkeypatch):
    """README: ``explain --cloud scene.ply --base "0.2 0.6 1.05" --target ...``: every check, the verdict."""
    truth = cli(files, "explain", "--cloud", str(files / "scene.ply"), "--base", "0.2 0.6 1.05",
                "--target", SCENE_TARGET)  # fmt: skip
    scene = upload(client, files / "scene.ply")
    svc = post(client, "/explain", {"scene_id": scene, "base": "0.2 0.6 1.05", "target": SCENE_TARGET})
    assert _valid(svc)["kind"] == "explain" and svc["scene_id"] == scene
    for key in ("exit_code", "error", "failures", "target", "base", "map", "footprint", "ik", "collisions",
                "motion", "verdict", "object"):  # fmt: skip
        assert svc[key] == truth[key], key
    # again, on the scene's kept segmentation and environment: neither segmented nor read from the cache
    import baseplace.terrain.cache
    import baseplace.terrain.pipeline

    made: list[str] = []
    for module, name in ((baseplace.terrain.pipeline, "terrain_from_points"),
                         (baseplace.terrain.cache, "cached_terrain")):  # fmt: skip
        monkeypatch.setattr(module, name, counted(getattr(module, name), made))
    again = post(client, "/explain", {"scene_id": scene, "base": "0.2 0.6 1.05", "target": SCENE_TARGET})
    assert again["verdict"] == truth["verdict"] and made == []
    # no scene: IK and self-collision only, as explain without --cloud
    truth = cli(files, "explain", "--base", "0.2 0.6 1.05", "--target", SCENE_TARGET)
    svc = post(client, "/explain", {"base": "0.2 0.6 1.05", "target": SCENE_TARGET})
    for key in ("exit_code", "map", "ik", "collisions", "motion", "verdict"):
        assert svc[key] == truth[key], key


def test_explain_takes_stand_on_and_clearance_as_the_cli(client, files):
    """``explain --stand-on any --clearance 0.02``: the service's fields answer what the CLI's options do."""
    args = ("--cloud", str(files / "scene.ply"), "--base", "0.2 0.6 1.05", "--target", SCENE_TARGET)
    truth = cli(files, "explain", *args, "--stand-on", "any", "--clearance", "0.02")
    scene = upload(client, files / "scene.ply")
    body = {"scene_id": scene, "base": "0.2 0.6 1.05", "target": SCENE_TARGET}
    svc = post(client, "/explain", {**body, "stand_on": "any", "clearance": 0.02})
    for key in ("exit_code", "error", "failures", "ik", "collisions", "motion", "verdict"):
        assert svc[key] == truth[key], key
    for bad in ({"stand_on": "table"}, {"clearance": -0.01}):
        assert client.post("/explain", json={**body, **bad}).status_code == 422
    refused = run_cli("explain", *args, "--stand-on", "table", "--map", str(files / "tiago.rmap"))
    assert refused.returncode == 2 and "--stand-on" in refused.stderr
