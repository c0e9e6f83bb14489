"""Occupancy grids in ROS map_server format, checked against nav2 map_server's own test oracle."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from baseplace.errors import InputError
from baseplace.world.occupancy import OccupancyGrid, load_occupancy
from conftest import SHARED

MAPS = SHARED / "maps"
TESTMAP = MAPS / "nav2_testmap"

# nav2_map_server/test/test_constants.cpp (ros-navigation/navigation2), g_valid_image_content:
# "row-major order, with the lower-left pixel first" -- the expected result of loading
# testmap.{png,pgm,bmp} with resolution 0.1, origin [2.0, 3.0, 1.0], free 0.196, occupied 0.65,
# trinary, negate 0 (test_map_io.cpp, MapIOTester::verifyMapMsg).
G_VALID_IMAGE_CONTENT = [
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    100, 100, 100, 100, 0, 0, 100, 100, 100, 0,
    100, 100, 100, 100, 0, 0, 100, 100, 100, 0,
    100, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    100, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    100, 0, 0, 0, 0, 0, 100, 100, 0, 0,
    100, 0, 0, 0, 0, 0, 100, 100, 0, 0,
    100, 0, 0, 0, 0, 0, 100, 100, 0, 0,
    100, 0, 0, 0, 0, 0, 100, 100, 0, 0,
    100, 0, 0, 0, 0, 0, 0, 0, 0, 0,
]  # fmt: skip
EXPECTED = np.array(G_VALID_IMAGE_CONTENT, dtype=np.int8).reshape(10, 10)

GOOD_YAML = {
    "image": "map.pgm",
    "resolution": 0.05,
    "origin": [1.0, -2.0, 0.5],
    "negate": 0,
    "occupied_thresh": 0.65,
    "free_thresh": 0.196,
}


def write_map(tmp_path: Path, image: str | Path | None, **fields: object) -> Path:
    """A map YAML in tmp_path: GOOD_YAML with ``image`` and any fields replaced (None drops a key)."""
    doc = {**GOOD_YAML, "image": None if image is None else str(image), **fields}
    lines = [f"{k}: {json.dumps(v)}" for k, v in doc.items() if v is not None]
    path = tmp_path / "map.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


# --- 1. nav2 map_server's test map ------------------------------------------------------------


def test_testmap_yaml_matches_nav2_constants():
    grid = load_occupancy(TESTMAP / "testmap.yaml")
    assert (grid.width, grid.height) == (10, 10)
    assert grid.resolution == pytest.approx(0.1)
    assert grid.origin == (2.0, 3.0, 1.0)
    assert grid.data.dtype == np.int8
    assert grid.to_json()["data"] == G_VALID_IMAGE_CONTENT


@pytest.mark.parametrize("ext", ["png", "pgm", "bmp"])
def test_testmap_every_image_format(tmp_path, ext):
    # as nav2's loadSaveValid{PNG,PGM,BMP}: the same parameters, each image
    path = write_map(tmp_path, TESTMAP / f"testmap.{ext}", resolution=0.1, origin=[2.0, 3.0, 1.0])
    grid = load_occupancy(path)
    np.testing.assert_array_equal(grid.data, EXPECTED)


def test_testmap_scale_mode_and_negate(tmp_path):
    grid = load_occupancy(write_map(tmp_path, TESTMAP / "testmap.png", mode="scale"))
    np.testing.assert_array_equal(grid.data, EXPECTED)  # only black and white pixels
    grid = load_occupancy(write_map(tmp_path, TESTMAP / "testmap.pgm", negate=1))
    np.testing.assert_array_equal(grid.data, 100 - EXPECTED)
    grid = load_occupancy(write_map(tmp_path, TESTMAP / "testmap.pgm", negate=True, mode="Trinary"))
    np.testing.assert_array_equal(grid.data, 100 - EXPECTED)


def test_testmap_raw_mode(tmp_path):
    # raw: cell = pixel value when in 0..100, else unknown; black pixels -> 0, white (255/254) -> -1
    grid = load_occupancy(write_map(tmp_path, TESTMAP / "testmap.pgm", mode="raw"))
    np.testing.assert_array_equal(grid.data, np.where(EXPECTED == 100, 0, -1))


def _saved_like_nav2(cells: np.ndarray, mode: str) -> np.ndarray:
    """The image nav2's saveMapToFile writes for ``cells`` (bottom row first), top row first."""
    known = (cells >= 0) & (cells <= 100)
    if mode == "raw":
        grey = np.where(known, cells, 255).astype(np.uint8)
        return grey[::-1]
    grey = np.where(known, np.rint((100.0 - cells) / 100.0 * 255), 128).astype(np.uint8)
    alpha = np.where(known, 255, 0).astype(np.uint8)
    return np.dstack([grey, grey, grey, alpha])[::-1]


@pytest.mark.parametrize("mode", ["scale", "raw"])
def test_nav2_save_load_modes(tmp_path, mode):
    # as nav2's loadSaveMapModes: save the test map in scale / raw mode, load it back, same grid
    for cells in (EXPECTED, np.where(np.arange(100).reshape(10, 10) % 7 == 0, -1, EXPECTED)):
        cv2.imwrite(str(tmp_path / "saved.png"), _saved_like_nav2(cells, mode))
        grid = load_occupancy(write_map(tmp_path, "saved.png", mode=mode))
        np.testing.assert_array_equal(grid.data, cells)


def test_scale_mode_intermediate_values(tmp_path):
    # occ = 1 - v/255; rint((occ - 0.196) / (0.65 - 0.196) * 100), worked out by hand:
    # v=200: occ 0.2157 -> 4.34 -> 4; v=128: 0.4980 -> 66.53 -> 67; v=100: 0.6078 -> 90.71 -> 91;
    # v=205 (the usual "unknown" grey): 0.1961 -> 0.0086 -> 0 (just above free_thresh)
    pixels = np.array([[200, 128, 100, 205, 0, 255]], dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "map.pgm"), pixels)
    grid = load_occupancy(write_map(tmp_path, "map.pgm", mode="scale"))
    assert grid.data.tolist() == [[4, 67, 91, 0, 100, 0]]
    grid = load_occupancy(write_map(tmp_path, "map.pgm"))
    assert grid.data.tolist() == [[-1, -1, -1, -1, 100, 0]]


def test_alpha_channel_as_map_server(tmp_path):
    # trinary averages alpha in as a 4th channel; scale makes any non-opaque pixel unknown
    rgba = np.array([[[255, 255, 255, 255], [255, 255, 255, 0], [0, 0, 0, 0], [0, 0, 0, 255]]], np.uint8)
    cv2.imwrite(str(tmp_path / "a.png"), rgba)
    # white+transparent: (3*255 + 0)/4 -> occ 0.25 -> unknown; black+transparent: occ 1 -> occupied
    assert load_occupancy(write_map(tmp_path, "a.png")).data.tolist() == [[0, -1, 100, 100]]
    assert load_occupancy(write_map(tmp_path, "a.png", mode="scale")).data.tolist() == [[0, -1, -1, 100]]


def test_colour_channels_averaged(tmp_path):
    # (255 + 0 + 0)/3 -> occ 2/3 > 0.65 -> occupied; (255 + 255 + 0)/3 -> occ 1/3 -> unknown
    bgr = np.array([[[0, 0, 255], [0, 255, 255], [255, 255, 255]]], np.uint8)
    cv2.imwrite(str(tmp_path / "c.bmp"), bgr)
    assert load_occupancy(write_map(tmp_path, "c.bmp")).data.tolist() == [[100, -1, 0]]


# --- 2. real maps ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "resolution", "origin", "free"),
    [
        ("depot", 0.05, (0.0, 0.0, 0.0), 0.25),
        ("tb3_sandbox", 0.05, (-10.0, -10.0, 0.0), 0.196),
        ("warehouse", 0.03, (-15.1, -25.0, 0.0), 0.1),
    ],
)
def test_real_maps(name, resolution, origin, free):
    grid = load_occupancy(MAPS / f"{name}.yaml")
    with Image.open(MAPS / f"{name}.pgm") as im:
        assert (grid.width, grid.height) == im.size
        pixels = np.asarray(im, dtype=float)
    assert grid.resolution == resolution
    assert grid.origin == origin
    assert grid.source == MAPS / f"{name}.yaml"
    assert set(np.unique(grid.data)) <= {-1, *range(101)}
    # independent decode (Pillow) and the trinary rule, top image row = last map row
    occ = 1.0 - pixels / 255.0
    oracle = np.where(occ > 0.65, 100, np.where(occ < free, 0, -1))[::-1]
    np.testing.assert_array_equal(grid.data, oracle)


# --- 3. geometry, inflation, clearance ---------------------------------------------------------


def test_cell_world_round_trip_with_yaw(rng):
    grid = OccupancyGrid(np.zeros((20, 30), np.int8), 0.1, (2.0, 3.0, 1.0))
    # cell (0, 0)'s centre by hand: origin + R(1 rad) @ (0.05, 0.05)
    c, s = math.cos(1.0), math.sin(1.0)
    np.testing.assert_allclose(grid.cell_to_world([[0, 0]]), [[2 + 0.05 * (c - s), 3 + 0.05 * (s + c)]])
    cells = np.column_stack([rng.integers(-5, 35, 200), rng.integers(-5, 25, 200)])
    np.testing.assert_array_equal(grid.world_to_cell(grid.cell_to_world(cells)), cells)
    # any point within half a cell of a centre (along the rotated axes) maps back to that cell
    local = rng.uniform(-0.049, 0.049, (200, 2))
    xy = grid.cell_to_world(cells) + local @ np.array([[c, s], [-s, c]])
    np.testing.assert_array_equal(grid.world_to_cell(xy), cells)
    on_map = (cells[:, 0] >= 0) & (cells[:, 0] < 30) & (cells[:, 1] >= 0) & (cells[:, 1] < 20)
    np.testing.assert_array_equal(grid.inside(xy), on_map)


def test_value_at_and_is_free():
    grid = load_occupancy(TESTMAP / "testmap.yaml")
    cells = np.array([[0, 1], [4, 1], [0, 0], [-1, 0], [10, 3]])
    xy = grid.cell_to_world(cells)
    assert grid.value_at(xy).tolist() == [100, 0, 0, -1, -1]
    assert grid.is_free(xy).tolist() == [False, True, True, False, False]
    data = EXPECTED.copy()
    data[5, 5] = -1
    unknown = OccupancyGrid(data, 0.1, grid.origin)
    centre = unknown.cell_to_world([[5, 5]])
    assert not unknown.is_free(centre)[0]
    assert unknown.is_free(centre, allow_unknown=True)[0]
    assert not unknown.is_free(unknown.cell_to_world([[-1, 5]]), allow_unknown=True)[0]


def _random_grid(rng, yaw=0.7):
    data = np.where(rng.random((13, 17)) < 0.06, 100, 0).astype(np.int8)
    data[rng.random(data.shape) < 0.1] = -1
    data[2, 3] = 100
    return OccupancyGrid(data, 0.1, (-1.0, 0.5, yaw))


def _brute_distances(grid):
    """Distance [m] from every cell centre to the nearest occupied centre, via world coordinates."""
    jj, ii = np.mgrid[0 : grid.height, 0 : grid.width]
    centres = grid.cell_to_world(np.column_stack([ii.ravel(), jj.ravel()]))
    occ = centres[grid.data.ravel() == 100]
    d = np.linalg.norm(centres[:, None, :] - occ[None, :, :], axis=2).min(axis=1)
    return d.reshape(grid.data.shape)


@pytest.mark.parametrize("radius", [0.0, 0.1, 0.15, 0.25, 0.3, 0.45])
def test_inflated_against_brute_force(rng, radius):
    grid = _random_grid(rng)
    oracle = np.where(_brute_distances(grid) <= radius + 1e-9, 100, grid.data)
    inflated = grid.inflated(radius)
    np.testing.assert_array_equal(inflated.data, oracle)
    assert (inflated.resolution, inflated.origin) == (grid.resolution, grid.origin)
    if radius == 0.1:  # the 4-neighbours of an isolated occupied cell, not the diagonals
        lone = OccupancyGrid(np.pad(np.array([[100]], np.int8), 2), 0.1)
        assert lone.inflated(radius).data.tolist() == [
            [0, 0, 0, 0, 0],
            [0, 0, 100, 0, 0],
            [0, 100, 100, 100, 0],
            [0, 0, 100, 0, 0],
            [0, 0, 0, 0, 0],
        ]


def test_clearance_against_brute_force(rng):
    grid = _random_grid(rng, yaw=-2.0)
    brute = _brute_distances(grid)
    cells = np.column_stack([rng.integers(0, grid.width, 100), rng.integers(0, grid.height, 100)])
    xy = grid.cell_to_world(cells + rng.uniform(-0.45, 0.45, (100, 2)))
    np.testing.assert_allclose(grid.clearance(xy), brute[cells[:, 1], cells[:, 0]], atol=1e-12)
    assert grid.clearance(grid.cell_to_world([[3, 2], [-1, 0]])).tolist() == [0.0, 0.0]
    empty = OccupancyGrid(np.zeros((3, 3), np.int8), 0.1)
    assert np.isinf(empty.clearance([[0.15, 0.15]])).all()


def test_to_json():
    grid = load_occupancy(TESTMAP / "testmap.yaml")
    doc = json.loads(json.dumps(grid.to_json()))
    assert set(doc) == {"width", "height", "resolution", "origin", "data"}
    assert (doc["width"], doc["height"], doc["resolution"], doc["origin"]) == (10, 10, 0.1, [2.0, 3.0, 1.0])
    assert doc["data"][:10] == [0] * 10  # bottom row first
    assert doc["data"][10:20] == [100, 100, 100, 100, 0, 0, 100, 100, 100, 0]


# --- 4. bad input ------------------------------------------------------------------------------


def _raises(path: Path, *words: str) -> str:
    with pytest.raises(InputError) as err:
        load_occupancy(path)
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg
    return msg


def _with_image(tmp_path: Path, data: bytes, name: str = "map.pgm", **fields: object) -> Path:
    (tmp_path / name).write_bytes(data)
    image = fields.pop("image", name)
    return write_map(tmp_path, image if image is None else str(image), **fields)


def test_missing_and_unparsable_yaml(tmp_path):
    _raises(tmp_path / "nope.yaml", "not found", "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: [unclosed\nresolution: 0.05\n")
    _raises(bad, "cannot parse map YAML", "bad.yaml at line 2, column 11")
    for text in ("- a\n- b\n", "", "just a string\n"):
        bad.write_text(text)
        _raises(bad, "mapping", "image, resolution, origin")
    bad.write_bytes(b"\xff\xfe\x00garbage")
    _raises(bad, "bad.yaml")


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"])
def test_missing_key(tmp_path, key):
    path = _with_image(tmp_path, (TESTMAP / "testmap.pgm").read_bytes(), **{key: None})
    _raises(path, f"missing key '{key}'", "required: image, resolution, origin, negate")


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"mode": "ternary"}, ("unknown map mode 'ternary'", "valid: raw, scale, trinary")),
        ({"mode": ""}, ("unknown map mode", "valid: raw, scale, trinary")),
        ({"resolution": 0}, ("'resolution' must be > 0",)),
        ({"resolution": -0.05}, ("'resolution' must be > 0",)),
        ({"resolution": "fine"}, ("'resolution' must be a finite number",)),
        ({"occupied_thresh": 1.5}, ("0 <= free_thresh < occupied_thresh <= 1",)),
        ({"free_thresh": -0.1}, ("0 <= free_thresh < occupied_thresh <= 1",)),
        ({"free_thresh": 0.7}, ("0 <= free_thresh < occupied_thresh <= 1",)),
        ({"free_thresh": 0.65}, ("0 <= free_thresh < occupied_thresh <= 1",)),
        ({"occupied_thresh": "high"}, ("'occupied_thresh' must be a finite number",)),
        ({"origin": [1.0, 2.0]}, ("'origin' must be 3 numbers [x, y, yaw]",)),
        ({"origin": [1.0, 2.0, 0.0, 0.0]}, ("'origin' must be 3 numbers",)),
        ({"origin": [1.0, 2.0, "x"]}, ("'origin' must be 3 numbers",)),
        ({"origin": "zero"}, ("'origin' must be 3 numbers",)),
        ({"negate": "maybe"}, ("'negate' must be 0, 1, true or false",)),
        ({"image": ""}, ("'image' must be a non-empty file name",)),
    ],
)
def test_bad_fields(tmp_path, fields, words):
    _raises(_with_image(tmp_path, (TESTMAP / "testmap.pgm").read_bytes(), **fields), *words)


def test_bad_images(tmp_path, capfd):
    _raises(write_map(tmp_path, "absent.pgm"), "map image not found", "absent.pgm")
    _raises(write_map(tmp_path, "map.jpg"), "unknown map image format '.jpg'", "valid: .bmp, .pgm, .png")
    _raises(write_map(tmp_path, "map"), "unknown map image format", "valid: .bmp, .pgm, .png")
    depot = (MAPS / "depot.pgm").read_bytes()
    png = (TESTMAP / "testmap.png").read_bytes()
    bmp = (TESTMAP / "testmap.bmp").read_bytes()
    for name, data in [
        ("map.pgm", depot[: len(depot) // 2]),  # truncated
        ("map.pgm", b""),
        ("map.png", b"this is not an image\n" * 10),
        ("map.png", png[: len(png) // 2]),
        ("map.bmp", bmp[:40]),
        ("map.png", depot),  # a PGM under a .png name still decodes, as GraphicsMagick would
    ]:
        path = _with_image(tmp_path, data, name)
        if data is depot:
            assert load_occupancy(path).data.shape == (307, 604)
        else:
            _raises(path, "cannot read map image", name)
    assert "Traceback" not in capfd.readouterr().err


def test_image_path_relative_to_yaml(tmp_path):
    sub = tmp_path / "maps"
    sub.mkdir()
    shutil.copy(TESTMAP / "testmap.png", sub / "testmap.png")
    yaml_path = write_map(sub, "testmap.png")
    np.testing.assert_array_equal(load_occupancy(str(yaml_path)).data, EXPECTED)
