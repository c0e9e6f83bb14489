"""A scene's inputs on upload (issue 29, item 2): transform and floor within limits, writes atomic.

The upload's ``transform`` is numbers only (a request never names a file of the server); the
floor's size is checked before it is made; a full disk is one 400 line and leaves no file.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("fastapi")

from fastapi.testclient import TestClient

from test_disk_full import FULL, small_disk  # noqa: F401  the fixture
from test_serve import UP, make_app, npy_bytes


def floor_cloud(side: float = 2.0, step: float = 0.05) -> np.ndarray:
    xy = np.mgrid[0:side:step, 0:side:step].reshape(2, -1).T
    return np.c_[xy, np.zeros(len(xy))]


@pytest.fixture(scope="module")
def client(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map)) as c:
        yield c


def upload(client: TestClient, points: np.ndarray, **params: object):
    return client.post("/scenes", params={"format": "npy", **params}, content=npy_bytes(points), headers=UP)


def test_a_transform_is_numbers_and_never_a_file_of_the_server(client, tmp_path):
    z_up = floor_cloud()
    tilted = z_up @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T  # up is +y in the sensor frame
    r = upload(client, tilted, transform="0 1 0")
    assert r.status_code == 200, r.text
    held = client.app.state.service.scene(r.json()["scene_id"]).cache.points
    assert np.allclose(held[:, 2], 0.0, atol=1e-12)  # the floor is level again
    secret = tmp_path / "T.txt"
    secret.write_text("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")  # a valid transform file on the server
    for spec in (str(secret), "0 1", "a b c", "nan 0 1"):
        r = upload(client, tilted, transform=spec)
        assert r.status_code == 400, (spec, r.text)
        assert "give the sensor-frame up vector 'ux uy uz' or the 16 numbers" in r.json()["error"]
    shear = "1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1"
    r = upload(client, z_up, transform=shear)
    assert r.status_code == 400 and "is not a rotation" in r.json()["error"]
    assert "baseplace-serve-" not in r.json()["error"]  # the scene's file, no path of the server
    r = client.post("/scenes", params={"format": "mcap", "cloud_topic": "/p", "transform": "0 0 1"},
                    content=b"x", headers=UP)  # fmt: skip
    assert r.status_code == 400 and "posed by its /tf" in r.json()["error"]


def test_a_floor_is_added_under_the_cloud_within_its_limit(client):
    table = floor_cloud(1.0) + np.array([0.0, 0.0, 0.74])  # a table top with no floor around it
    r = upload(client, table, floor=0.0)
    assert r.status_code == 200, r.text
    held = client.app.state.service.scene(r.json()["scene_id"]).cache.points
    assert len(held) > len(table) and np.isclose(held[:, 2].min(), 0.0)
    # 1 km wide: 2.5e9 floor points, refused before any is made
    wide = np.array([[0.0, 0.0, 0.0], [1000.0, 1000.0, 0.0], [500.0, 500.0, 0.5]])
    r = upload(client, wide, floor=-0.1, transform="0 0 1")  # z up as given: no up check of 3 points
    assert r.status_code == 400
    assert re.search(r"floor under the cloud .* over the limit of 4e\+06", r.json()["error"]), r.json()
    r = upload(client, table, floor=2.0)  # above the cloud: the CLI's line
    assert r.status_code == 400 and "below the cloud's top" in r.json()["error"]


def test_uploads_on_a_full_disk_are_one_line_and_leave_no_file(tiago, tiago_map, small_disk):  # noqa: F811
    import cv2

    app = make_app(tiago, tiago_map)
    with small_disk(4096) as disk, TestClient(app) as c:
        state = app.state.service
        state.folder = disk.path  # the service's scene files on the small disk
        r = upload(c, floor_cloud())
        assert r.status_code == 200, r.text
        scene_id = r.json()["scene_id"]
        before = sorted(p.name for p in disk.path.rglob("*"))
        ok, png = cv2.imencode(".png", np.full((400, 400), 254, np.uint8))
        assert ok
        disk.fill(leave_kb=0)
        with disk.limited():
            r = upload(c, floor_cloud())
            grid = c.post(f"/scenes/{scene_id}/grid", params={"resolution": 0.05, "format": "png"},
                          content=png.tobytes(), headers=UP)  # fmt: skip
        for answer in (r, grid):
            assert answer.status_code == 400, answer.text
            line = answer.json()["error"]
            assert FULL.search(line) and "\n" not in line and "baseplace-serve-" not in line, line
        assert disk.temporaries() == []
        assert sorted(p.name for p in disk.path.rglob("*") if p.name != "filler") == before
