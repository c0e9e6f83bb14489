from __future__ import annotations

import importlib
import struct
from pathlib import Path

import lzf
import numpy as np
import pyoctomap
import pytest

from baseplace.errors import InputError
from baseplace.terrain import io as terrain_io
from baseplace.terrain.io import Cloud, load_cloud, load_transform, save_cloud, up_vector_transform

CLOUDS = Path(__file__).resolve().parents[2] / "shared" / "data" / "pointclouds"
MUG = CLOUDS / "table_scene_mug_stereo_textured.pcd"
OFFICE = CLOUDS / "office1.pcd"
PLANE = CLOUDS / "sac_plane_test.pcd"


def _raises_one_line(match: str, fn, *args) -> str:
    with pytest.raises(InputError, match=match) as info:
        fn(*args)
    message = str(info.value)
    assert "\n" not in message and "Traceback" not in message
    return message


# --- an independent PCD oracle: parse the header and decode only x, y, z and the color column ---


def _pcd_oracle(path: Path) -> tuple[dict[str, list[str]], np.ndarray, np.ndarray | None]:
    """Returns (header, xyz (N, 3) float32 incl. NaN, packed color uint32 (N,) or None)."""
    blob = path.read_bytes()
    header: dict[str, list[str]] = {}
    offset = 0
    while True:
        end = blob.index(b"\n", offset)
        line = blob[offset:end].decode().strip()
        offset = end + 1
        if line and not line.startswith("#"):
            key, *values = line.split()
            header[key.upper()] = values
            if key.upper() == "DATA":
                break
    fields, n = header["FIELDS"], int(header["POINTS"][0])
    sizes = [int(s) for s in header["SIZE"]]
    assert all(int(c) == 1 for c in header["COUNT"]) and all(s == 4 for s in sizes)
    color = next((f for f in ("rgb", "rgba") if f in fields), None)
    encoding = header["DATA"][0]
    if encoding == "ascii":
        table = np.loadtxt(blob[offset:].decode().splitlines(), dtype=str, ndmin=2)
        xyz = table[:, [fields.index(f) for f in "xyz"]].astype(np.float32)
        packed = None if color is None else table[:, fields.index(color)].astype(np.float64).astype(np.uint32)
        return header, xyz, packed
    assert encoding == "binary_compressed"
    compressed, uncompressed = struct.unpack("<II", blob[offset : offset + 8])
    raw = lzf.decompress(blob[offset + 8 : offset + 8 + compressed], uncompressed)
    columns = {f: raw[i * 4 * n : (i + 1) * 4 * n] for i, f in enumerate(fields)}  # one column per field
    xyz = np.column_stack([np.frombuffer(columns[f], dtype="<f4") for f in "xyz"])
    packed = None if color is None else np.frombuffer(columns[color], dtype="<u4")
    return header, xyz, packed


def _unpack(packed: np.ndarray) -> np.ndarray:
    return np.column_stack([(packed >> s) & 0xFF for s in (16, 8, 0)]).astype(np.uint8)


@pytest.mark.parametrize("path", [MUG, OFFICE, PLANE], ids=lambda p: p.stem)
def test_real_pcd_files_load_their_finite_points(path):
    from pypcd4 import PointCloud

    header, xyz, packed = _pcd_oracle(path)
    finite = np.isfinite(xyz).all(axis=1)
    assert len(xyz) == int(header["POINTS"][0])
    raw = PointCloud.from_path(path).numpy(("x", "y", "z"))
    assert len(raw) == len(xyz) and np.isfinite(raw).all(axis=1).sum() == finite.sum()

    cloud = load_cloud(path)
    assert len(cloud) == finite.sum() > 0
    assert cloud.points.dtype == np.float64 and np.isfinite(cloud.points).all()
    np.testing.assert_array_equal(cloud.points, xyz[finite].astype(np.float64))
    assert cloud.source == str(path)
    width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
    assert (cloud.width, cloud.height) == ((width, height) if height > 1 else (None, None))
    if packed is None:
        assert cloud.colors is None
    else:
        assert cloud.colors is not None and cloud.colors.dtype == np.uint8
        np.testing.assert_array_equal(cloud.colors, _unpack(packed[finite]))


def test_mug_scene_is_organized_with_a_third_missing():
    cloud = load_cloud(MUG)
    assert (cloud.width, cloud.height) == (640, 480)
    assert 0.25 < 1 - len(cloud) / (640 * 480) < 0.4
    assert cloud.colors is not None and cloud.colors.std() > 10  # real texture, not a constant


def test_hand_written_ascii_pcd_loads(tmp_path):
    path = tmp_path / "hand.pcd"
    path.write_text(
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n"
        f"0.5 -1.25 2 {0xFF8000}\nnan nan nan 0\n1 2 3 {0x0000FF}\n"
    )
    cloud = load_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[0.5, -1.25, 2.0], [1.0, 2.0, 3.0]])
    assert cloud.colors is not None
    np.testing.assert_array_equal(cloud.colors, [[255, 128, 0], [0, 0, 255]])
    assert cloud.width is None and cloud.height is None


def test_xyz_text_loads_first_three_columns(tmp_path):
    path = tmp_path / "scan.xyz"
    path.write_text("# x y z intensity\n1 2 3 9\n4,5,6,9\n\ninf 0 0 1\n7\t8\t9 1\n")
    cloud = load_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert cloud.colors is None


# --- round trips ---


@pytest.fixture()
def cloud() -> Cloud:
    rng = np.random.default_rng(7)
    points = rng.normal(scale=3.0, size=(500, 3))
    colors = rng.integers(0, 256, size=(500, 3), dtype=np.uint8)
    return Cloud(points, colors, "random")


@pytest.mark.parametrize("with_colors", [True, False])
def test_ply_round_trip_is_exact_in_float64(tmp_path, cloud, with_colors):
    source = cloud if with_colors else Cloud(cloud.points)
    save_cloud(source, tmp_path / "c.ply")
    assert (tmp_path / "c.ply").read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    back = load_cloud(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.points, source.points)
    if with_colors:
        assert back.colors is not None and cloud.colors is not None
        np.testing.assert_array_equal(back.colors, cloud.colors)
    else:
        assert back.colors is None


def test_pcd_round_trip_is_exact_in_float32(tmp_path, cloud):
    save_cloud(cloud, tmp_path / "c.pcd")
    header, xyz, packed = _pcd_oracle_binary(tmp_path / "c.pcd")
    assert header["DATA"] == ["binary"] and header["FIELDS"] == ["x", "y", "z", "rgb"]
    back = load_cloud(tmp_path / "c.pcd")
    np.testing.assert_array_equal(back.points, cloud.points.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(xyz, cloud.points.astype(np.float32))
    assert back.colors is not None and cloud.colors is not None
    np.testing.assert_array_equal(back.colors, cloud.colors)
    np.testing.assert_array_equal(_unpack(packed), cloud.colors)


def _pcd_oracle_binary(path: Path) -> tuple[dict[str, list[str]], np.ndarray, np.ndarray]:
    blob = path.read_bytes()
    head, data = blob.split(b"DATA binary\n", 1)
    header = {k: v for k, *v in (line.split() for line in head.decode().splitlines() if line)}
    header["DATA"] = ["binary"]
    records = np.frombuffer(data, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    return header, np.column_stack([records[f] for f in "xyz"]), records["rgb"]


def test_npy_round_trip_is_exact(tmp_path, cloud):
    save_cloud(cloud, tmp_path / "c.npy")
    back = load_cloud(tmp_path / "c.npy")
    np.testing.assert_array_equal(back.points, cloud.points)
    assert back.colors is None  # .npy holds points only


def test_npy_with_extra_columns_and_nan_rows(tmp_path):
    array = np.arange(20, dtype=np.float32).reshape(4, 5)
    array[1, 2] = np.nan
    np.save(tmp_path / "c.npy", array)
    np.testing.assert_array_equal(load_cloud(tmp_path / "c.npy").points, array[[0, 2, 3], :3])


def test_save_is_atomic_and_leaves_nothing_on_failure(tmp_path, cloud, monkeypatch):
    target = tmp_path / "c.ply"
    save_cloud(cloud, target)
    before = target.read_bytes()

    def broken_writer(cloud, f):
        f.write(b"half a file")
        raise OSError("disk full")

    monkeypatch.setitem(terrain_io._WRITERS, ".ply", broken_writer)
    with pytest.raises(OSError, match="disk full"):
        save_cloud(cloud, target)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply"]


def test_save_rejects_unknown_suffix_and_missing_directory(tmp_path, cloud):
    message = _raises_one_line("unknown suffix '.las'", save_cloud, cloud, tmp_path / "c.las")
    assert ".npy, .pcd, .ply" in message
    _raises_one_line("does not exist", save_cloud, cloud, tmp_path / "no" / "c.ply")


# --- OctoMap .bt ---


def test_octomap_round_trip_expands_pruned_leaves(tmp_path):
    resolution = 0.05
    rng = np.random.default_rng(3)
    scattered = rng.uniform([-1.0, -1.0, 0.0], [1.0, 1.0, 0.5], size=(300, 3))
    # an aligned 8x8x8 block of voxels is pruned by octomap into a few large leaves
    block = (np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * resolution
    block += [2.0, 2.0, 2.0]
    free = rng.uniform([-1.0, -1.0, -2.0], [1.0, 1.0, -1.0], size=(50, 3))
    tree = pyoctomap.OcTree(resolution)
    for p in np.vstack([scattered, block]):
        tree.updateNode(p, True)
    for p in free:
        tree.updateNode(p, False)
    tree.updateInnerOccupancy()
    assert any(leaf.getSize() > 1.5 * resolution for leaf in tree.begin_leafs())  # pruning happened
    path = tmp_path / "scene.bt"
    assert tree.writeBinary(str(path))

    cloud = load_cloud(path)
    occupied = np.vstack([scattered, block])
    expected = np.unique(np.floor(occupied / resolution).astype(np.int64), axis=0)
    keys = np.floor(cloud.points / resolution).astype(np.int64)
    assert len(cloud) == len(expected)
    np.testing.assert_array_equal(np.unique(keys, axis=0), expected)
    np.testing.assert_allclose(cloud.points, (keys + 0.5) * resolution, rtol=0, atol=1e-12)
    # every inserted point lies within half a voxel (per axis) of a returned centre
    centres = {tuple(k) for k in keys}
    for p in occupied:
        k = tuple(np.floor(p / resolution).astype(np.int64))
        assert k in centres
        assert np.all(np.abs(p - (np.array(k) + 0.5) * resolution) <= resolution / 2 + 1e-12)
    assert not np.any(cloud.points[:, 2] < -0.5)  # free voxels are not points


def test_truncated_or_foreign_octomap_is_an_input_error(tmp_path):
    tree = pyoctomap.OcTree(0.1)
    for p in np.random.default_rng(1).uniform(-1, 1, size=(200, 3)):
        tree.updateNode(p, True)
    full = tmp_path / "full.bt"
    assert tree.writeBinary(str(full))
    blob = full.read_bytes()
    for cut in (60, len(blob) // 2, len(blob) - 2):
        (tmp_path / "cut.bt").write_bytes(blob[:cut])
        _raises_one_line("cut.bt", load_cloud, tmp_path / "cut.bt")
    (tmp_path / "foreign.bt").write_bytes(b"\x00\x01 not an octree")
    _raises_one_line("not an OctoMap binary file", load_cloud, tmp_path / "foreign.bt")


# --- bad input ---


def test_missing_file_and_unknown_suffix(tmp_path):
    _raises_one_line("does not exist", load_cloud, tmp_path / "nothing.pcd")
    _raises_one_line("the limit is 255", load_cloud, tmp_path / ("a" * 300 + ".pcd"))  # not an OSError
    message = _raises_one_line("unknown suffix '.las'", load_cloud, tmp_path / "scan.las")
    assert ".bt, .npy, .pcd, .ply, .txt, .xyz" in message


def test_truncated_real_pcd_is_an_input_error(tmp_path):
    for source in (MUG, PLANE):
        blob = source.read_bytes()
        cut = tmp_path / f"half_{source.name}"
        cut.write_bytes(blob[: len(blob) // 2])
        _raises_one_line("truncated or corrupt", load_cloud, cut)


def test_binary_pcd_cut_on_a_record_boundary_is_an_input_error(tmp_path, cloud):
    save_cloud(cloud, tmp_path / "c.pcd")
    blob = (tmp_path / "c.pcd").read_bytes()
    header_len = blob.index(b"DATA binary\n") + len(b"DATA binary\n")
    (tmp_path / "cut.pcd").write_bytes(blob[: header_len + 100 * 16])
    _raises_one_line("header says 500 points .* data holds 100", load_cloud, tmp_path / "cut.pcd")


def test_truncated_ply_is_an_input_error(tmp_path, cloud):
    save_cloud(cloud, tmp_path / "c.ply")
    blob = (tmp_path / "c.ply").read_bytes()
    (tmp_path / "cut.ply").write_bytes(blob[: len(blob) // 2])
    _raises_one_line("truncated or corrupt", load_cloud, tmp_path / "cut.ply")


def test_empty_and_all_nan_clouds_are_input_errors(tmp_path):
    save_cloud(Cloud(np.empty((0, 3))), tmp_path / "empty.ply")
    _raises_one_line("has no finite points", load_cloud, tmp_path / "empty.ply")
    np.save(tmp_path / "nan.npy", np.full((10, 3), np.nan))
    _raises_one_line("has no finite points", load_cloud, tmp_path / "nan.npy")
    (tmp_path / "nan.pcd").write_text(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\nnan nan nan\nnan nan nan\n"
    )
    _raises_one_line("has no finite points", load_cloud, tmp_path / "nan.pcd")
    (tmp_path / "empty.xyz").write_text("# nothing here\n")
    _raises_one_line("has no finite points", load_cloud, tmp_path / "empty.xyz")


def test_malformed_arrays_and_text_are_input_errors(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros(9))
    _raises_one_line(r"\(N, 3\)", load_cloud, tmp_path / "flat.npy")
    np.save(tmp_path / "two.npy", np.zeros((4, 2)))
    _raises_one_line(r"got shape \(4, 2\)", load_cloud, tmp_path / "two.npy")
    (tmp_path / "two.xyz").write_text("1 2\n3 4\n")
    _raises_one_line("truncated or corrupt", load_cloud, tmp_path / "two.xyz")
    (tmp_path / "noxyz.pcd").write_text(
        "VERSION 0.7\nFIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n"
    )
    _raises_one_line("no field x, y, z; fields: a, b, c", load_cloud, tmp_path / "noxyz.pcd")


def test_cloud_validates_its_arrays():
    _raises_one_line(r"shape \(N, 3\)", Cloud, np.zeros((4, 2)))
    _raises_one_line("must be finite", Cloud, np.array([[0.0, np.nan, 1.0]]))
    _raises_one_line("uint8", Cloud, np.zeros((2, 3)), np.zeros((2, 3), dtype=np.int64))


# --- transforms ---


def test_transform_file_with_comments_and_commas(tmp_path, cloud):
    T = np.eye(4)
    T[:3, :3] = up_vector_transform([0.3, -0.2, 0.9])[:3, :3]
    T[:3, 3] = [1.0, -2.0, 0.5]
    path = tmp_path / "T_world_sensor.txt"
    rows = "\n".join(", ".join(repr(float(v)) for v in row) + "  # row" for row in T)
    path.write_text(f"# world_T_sensor\n{rows}\n")
    np.testing.assert_array_equal(load_transform(str(path)), T)
    moved = cloud.transformed(T)
    np.testing.assert_allclose(moved.points, (T @ np.c_[cloud.points, np.ones(len(cloud))].T).T[:, :3])
    assert moved.colors is cloud.colors and moved.source == cloud.source


@pytest.mark.parametrize(
    "spec", ["0 0 1", "0 0 -1", "0 -1 0", "0, 0, 2", "1 0 0", "1e-9 0 -1", "-3 4 0.5", "0.2 -0.1 -5"]
)
def test_up_vector_maps_onto_plus_z_with_the_minimal_rotation(spec):
    T = load_transform(spec)
    up = np.array([float(v) for v in spec.replace(",", " ").split()])
    u = up / np.linalg.norm(up)
    R = T[:3, :3]
    np.testing.assert_allclose(R @ u, [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_array_equal(T[:3, 3], 0)
    # minimal: the rotation angle equals the angle between up and +z
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    assert angle == pytest.approx(np.arccos(np.clip(u[2], -1, 1)), abs=1e-7)


def test_up_vector_special_cases_are_exact():
    np.testing.assert_array_equal(up_vector_transform([0, 0, 1]), np.eye(4))
    np.testing.assert_array_equal(up_vector_transform([0, 0, -1])[:3, :3], np.diag([1.0, -1.0, -1.0]))
    # a camera's optical frame: y points down, so up is -y
    R = up_vector_transform([0, -1, 0])[:3, :3]
    np.testing.assert_allclose(R @ [0, -1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(R @ [1, 0, 0], [1, 0, 0], atol=1e-15)  # x, the rotation axis, stays


def _write(tmp_path: Path, name: str, text: str) -> str:
    (tmp_path / name).write_text(text)
    return str(tmp_path / name)


def test_bad_transforms_are_input_errors(tmp_path):
    scaled = "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n"
    _raises_one_line("not a rotation", load_transform, _write(tmp_path, "scaled.txt", scaled))
    mirror = "1 0 0 0\n0 1 0 0\n0 0 -1 0\n0 0 0 1\n"
    _raises_one_line("reflection", load_transform, _write(tmp_path, "mirror.txt", mirror))
    last_row = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n"
    _raises_one_line("last row must be 0 0 0 1", load_transform, _write(tmp_path, "row.txt", last_row))
    fifteen = " ".join(["0"] * 15)
    _raises_one_line(
        "holds 15 numbers; a 4x4 matrix needs 16", load_transform, _write(tmp_path, "15.txt", fifteen)
    )
    nan = "nan 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"
    _raises_one_line("NaN", load_transform, _write(tmp_path, "nan.txt", nan))
    words = "identity\n"
    _raises_one_line("only numbers", load_transform, _write(tmp_path, "words.txt", words))
    _raises_one_line(
        "neither an existing file nor an up vector", load_transform, str(tmp_path / "missing.txt")
    )
    _raises_one_line("needs 3 numbers", load_transform, "0 1")
    _raises_one_line("needs 3 numbers", load_transform, fifteen)
    _raises_one_line("must be finite", load_transform, "nan 0 1")
    _raises_one_line("must be non-zero", load_transform, "0 0 0")
    _raises_one_line("must be non-zero", up_vector_transform, [0.0, 0.0, 0.0])
    _raises_one_line("last row", Cloud(np.zeros((1, 3))).transformed, np.ones((4, 4)))
    _raises_one_line(r"\(4, 4\)", Cloud(np.zeros((1, 3))).transformed, np.eye(3))


def test_terrain_public_names_import():
    module = importlib.import_module("baseplace.terrain")
    assert set(module.__all__) == {
        "Cloud",
        "load_cloud",
        "load_transform",
        "save_cloud",
        "up_vector_transform",
    }
    for name in module.__all__:
        assert getattr(module, name) is not None
