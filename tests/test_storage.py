from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.storage import FORMAT_VERSION, load_map, save_map


@pytest.fixture(scope="module")
def small_map(planar3):
    return build_map(planar3, None, BuildSettings(samples=100_000, seed=4, manipulability=True))


def test_roundtrip_is_exact(small_map, planar3, tmp_path):
    path = tmp_path / "m.rmap"
    size = save_map(small_map, path)
    assert size == path.stat().st_size > 0
    loaded = load_map(path, planar3)
    np.testing.assert_array_equal(loaded.cells, small_map.cells)
    np.testing.assert_array_equal(loaded.counts, small_map.counts)
    np.testing.assert_array_equal(loaded.manipulability, small_map.manipulability)
    assert loaded.info == small_map.info and loaded.grid == small_map.grid
    assert [p.name for p in tmp_path.iterdir()] == ["m.rmap"]  # no temporary left behind


def test_failed_write_leaves_nothing(small_map, tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(h5py.File, "create_dataset", boom)
    with pytest.raises(RuntimeError):
        save_map(small_map, tmp_path / "m.rmap")
    assert list(tmp_path.iterdir()) == []


def test_truncated_map(small_map, tmp_path):
    path = tmp_path / "m.rmap"
    save_map(small_map, path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated or corrupt"):
        load_map(path)


def test_newer_format_and_wrong_robot(small_map, tiago, planar3, tmp_path):
    path = tmp_path / "m.rmap"
    save_map(small_map, path)
    with pytest.raises(InputError, match="built for robot 'planar3', not 'tiago'"):
        load_map(path, tiago)
    with pytest.raises(InputError, match="arm 'arm', not 'left'"):
        load_map(path, planar3, "left")
    other_urdf = dataclasses.replace(small_map.info, urdf_sha256="0" * 64)
    save_map(dataclasses.replace(small_map, info=other_urdf), path)
    with pytest.raises(InputError, match="different URDF"):
        load_map(path, planar3)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = FORMAT_VERSION + 1
    with pytest.raises(InputError, match="newer than this baseplace"):
        load_map(path)


def test_header_texts_are_checksummed(small_map, tmp_path):
    path = tmp_path / "m.rmap"
    save_map(small_map, path)
    with h5py.File(path, "a") as f:
        text = bytes(f["info"][()]).replace(b'"planar3"', b'"planar4"')
        del f["info"]
        f["info"] = np.frombuffer(text, dtype=np.uint8)
    with pytest.raises(InputError, match="checksum"):
        load_map(path)


def test_format_version_1_is_refused_unread(small_map, tmp_path):
    """Version 1 kept grid and info in variable-length string attributes, which are never read now."""
    path = tmp_path / "v1.rmap"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "baseplace-reachability-map"
        f.attrs["format_version"] = 1
        f.attrs["grid"] = "{}"
        f["cells"] = small_map.cells
    with pytest.raises(
        InputError, match="format version 1, from an older baseplace; rebuild it with build-map"
    ):
        load_map(path)


def test_no_variable_length_strings_in_the_file(small_map, tmp_path):
    path = tmp_path / "m.rmap"
    save_map(small_map, path)
    with h5py.File(path, "r") as f:  # variable-length strings have numpy kind "O"
        assert all(f.attrs.get_id(name).dtype.kind != "O" for name in f.attrs), dict(f.attrs)
        assert all(f[name].dtype.kind != "O" for name in f), list(f)


def test_corrupt_data_and_foreign_files(small_map, tmp_path):
    path = tmp_path / "m.rmap"
    save_map(small_map, path)
    with h5py.File(path, "a") as f:
        counts = f["counts"][()]
        counts[0] += 1
        f["counts"][...] = counts
    with pytest.raises(InputError, match="checksum"):
        load_map(path)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    with pytest.raises(InputError, match="not a baseplace reachability map"):
        load_map(other)
    with pytest.raises(InputError, match="does not exist"):
        load_map(tmp_path / "missing.rmap")
