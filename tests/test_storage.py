from __future__ import annotations

import json

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
    with h5py.File(path, "a") as f:
        info = json.loads(f.attrs["info"])
        info["urdf_sha256"] = "0" * 64
        f.attrs["info"] = json.dumps(info)
    with pytest.raises(InputError, match="different URDF"):
        load_map(path, planar3)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = FORMAT_VERSION + 1
    with pytest.raises(InputError, match="newer than this baseplace"):
        load_map(path)


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
