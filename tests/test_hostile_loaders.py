"""Hostile clouds and HDF5 files of issue 28: sizes the old checks missed, and files that name others.

Each file is loaded in a fresh process under ``BASEPLACE_MAX_MEMORY_MB=512`` (and an address-space
limit, so that a loader that ignores the cap fails instead of taking the machine); the growth of
its resident memory (``VmHWM`` minus the resident set after the imports) must stay under
``LIMIT_MB``. The CLI reads the same file with the same cap: exit 2, one line, and its whole peak
(``ru_maxrss``, imports included) under the cap.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from peak_memory import CAP_MB, cli_peak
from test_hostile_files import _PROBE, SRC

LIMIT_MB = 200.0
ADDRESS_SPACE = 3 * 2**30  # far above what a capped load needs, far below this machine's memory
ENV = {**os.environ, "PYTHONPATH": SRC, "BASEPLACE_MAX_MEMORY_MB": str(CAP_MB)}


def _limit_address_space() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def probe(kind: str, path: Path, timeout: float = 120) -> dict[str, object]:
    proc = subprocess.run([sys.executable, "-c", _PROBE, kind, str(path)], capture_output=True, text=True,
                          timeout=timeout, env=ENV, preexec_fn=_limit_address_space)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def assert_refused(
    kind: str,
    path: Path,
    fragment: str,
    cli_args: list[str],
    timeout: float = 120,
    limit_mb: float = LIMIT_MB,
) -> None:
    result = probe(kind, path, timeout)
    assert str(result["outcome"]).startswith("error: "), result
    assert fragment in str(result["outcome"]), result
    assert float(result["peak_mb"]) < limit_mb, result  # type: ignore[arg-type]
    code, stderr, _, peak = cli_peak(*cli_args, timeout=timeout)
    assert code == 2, stderr[-2000:]
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and len(lines[0]) < 1000, stderr[-2000:]
    assert peak < CAP_MB, peak


# --- PCD -----------------------------------------------------------------------------------------

HUGE_COUNT_HEADER = (
    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1000000000\n"
    "WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA binary\n"
)


def test_pcd_with_a_long_comment_before_a_huge_count(tmp_path):
    path = tmp_path / "comment.pcd"
    path.write_bytes(b"# " + b"c" * 70_000 + b"\n" + HUGE_COUNT_HEADER.encode() + b"\0" * 12)
    assert 70_000 < path.stat().st_size < 71_000
    assert_refused("cloud", path, "can hold", ["segment", str(path)])


def test_pcd_of_no_points_with_a_huge_count(tmp_path):
    path = tmp_path / "empty.pcd"  # pypcd4 builds one numpy field per value even for no points
    path.write_bytes(HUGE_COUNT_HEADER.replace("WIDTH 1", "WIDTH 0").replace("POINTS 1", "POINTS 0").encode())
    assert_refused("cloud", path, "values per point", ["segment", str(path)])


def test_pcd_header_over_a_megabyte_is_refused(tmp_path):
    path = tmp_path / "long.pcd"
    path.write_bytes(b"#" * (2 * 2**20) + b"\n" + HUGE_COUNT_HEADER.encode())
    assert_refused("cloud", path, "header is longer than", ["segment", str(path)])


def _compressed_pcd(path: Path, n_points: int, uncompressed: int | None = None) -> None:
    import lzf

    data = bytes(12 * n_points)  # x, y, z float32 of every point, column by column, all zero
    compressed = lzf.compress(data)
    header = (f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n_points}\n"
              f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n_points}\nDATA binary_compressed\n")  # fmt: skip
    sizes = struct.pack("II", len(compressed), len(data) if uncompressed is None else uncompressed)
    path.write_bytes(header.encode() + sizes + compressed)


def test_compressed_pcd_is_checked_with_what_reading_it_takes(tmp_path):
    # 10 M points (120 MB of data, from 1.4 MB): the data fits the cap, reading it (the
    # decompressed buffer, the records, float64 copies) does not
    path = tmp_path / "zeros.pcd"
    _compressed_pcd(path, 10_000_000)
    assert path.stat().st_size < 2_000_000
    assert_refused("cloud", path, "over the limit", ["segment", str(path)])


def test_compressed_pcd_declaring_another_size_is_refused(tmp_path):
    path = tmp_path / "sizes.pcd"
    _compressed_pcd(path, 1000, uncompressed=4_000_000_000)
    assert_refused("cloud", path, "the compressed data says", ["segment", str(path)])


# --- PLY -----------------------------------------------------------------------------------------

PLY_VERTEX = b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_ply_of_empty_faces_reads_only_its_vertices(tmp_path, fmt):
    path = tmp_path / "faces.ply"
    n_faces = 8_000_000 if fmt != "ascii" else 4_000_000
    header = (b"ply\nformat " + fmt.encode() + b" 1.0\n" + PLY_VERTEX
              + b"element face %d\nproperty list uchar int vertex_indices\nend_header\n" % n_faces)  # fmt: skip
    body = struct.pack("<3f", 1, 2, 3) + bytes(n_faces) if fmt != "ascii" else b"1 2 3\n" + b"0\n" * n_faces
    path.write_bytes(header + body)
    assert path.stat().st_size >= 8_000_000
    result = probe("cloud", path)
    assert result["outcome"] == "loaded", result
    assert float(result["peak_mb"]) < LIMIT_MB, result  # type: ignore[arg-type]
    from baseplace.terrain.io import load_cloud

    np.testing.assert_array_equal(load_cloud(path).points, [[1.0, 2.0, 3.0]])


def test_ply_header_over_a_megabyte_is_refused(tmp_path):
    path = tmp_path / "long.ply"
    path.write_bytes(
        b"ply\nformat ascii 1.0\ncomment " + b"c" * (2 * 2**20) + b"\n" + PLY_VERTEX + b"end_header\n"
    )
    assert_refused("cloud", path, "header is longer than", ["segment", str(path)])


def test_ply_vertices_after_a_list_element(tmp_path):
    path = tmp_path / "after.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement face 1\n"
                     b"property list uchar int vertex_indices\n" + PLY_VERTEX + b"end_header\n\0"
                     + struct.pack("<3f", 1, 2, 3))  # fmt: skip
    assert_refused("cloud", path, "list properties comes before 'vertex'", ["segment", str(path)])


def test_ascii_ply_elements_before_the_vertices_are_skipped(tmp_path):
    path = tmp_path / "skip.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement camera 2\nproperty float f\n" + PLY_VERTEX.replace(b"1", b"2")
                     + b"property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
                     b"0.5\n0.25\n1 2 3 1 1 1\n4 5 6 255 0 9\n")  # fmt: skip
    from baseplace.terrain.io import load_cloud

    cloud = load_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.colors, [[1, 1, 1], [255, 0, 9]])  # uchar, never rescaled


# --- OctoMap, text, npy --------------------------------------------------------------------------


def test_full_octomap_is_refused_before_octomap_builds_it(tmp_path):
    # every inner node down to depth 7 has 8 inner children, depth 7's 8 occupied leaves:
    # 2.4 M records (4.8 MB) for 19 M nodes
    stream = b"\xaa\xaa"
    for _ in range(7):
        stream = b"\xff\xff" + stream * 8
    size = sum(8**d for d in range(9))
    path = tmp_path / "full.bt"
    path.write_bytes(b"# Octomap OcTree binary file\nid OcTree\nsize %d\nres 0.1\ndata\n" % size + stream)
    assert 4_700_000 < path.stat().st_size < 4_900_000
    assert_refused("cloud", path, "nodes", ["segment", str(path)])


def test_xyz_text_is_capped_while_it_is_read(tmp_path):
    path = tmp_path / "zeros.xyz"
    path.write_bytes(b"0 0 0\n" * 8_000_000)  # 48 MB, 8 M points: 192 MB of float64, more in copies
    # refused once the points read so far (7.4 M, 180 MB) would take the cap in copies
    assert_refused("cloud", path, "over the limit", ["segment", str(path)], limit_mb=CAP_MB / 2)


def test_npy_of_python_objects_is_refused_without_unpickling(tmp_path):
    path = tmp_path / "objects.npy"
    marker = tmp_path / "ran"
    payload = np.empty(3, dtype=object)
    payload[0] = _Marker(str(marker))
    np.save(path, payload, allow_pickle=True)
    assert_refused("cloud", path, "Python objects", ["segment", str(path)])
    assert not marker.exists()


class _Marker:
    """Unpickling it would create the file ``path``."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


# --- HDF5: no file may make baseplace open another --------------------------------------------


def _hdf5_naming_a_fifo(tmp_path: Path, suffix: str, fmt: str, text: str, how: str) -> Path:
    """A file of format ``fmt`` whose text ``text`` lies in a FIFO: opening the FIFO blocks."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    path = tmp_path / f"hostile{suffix}"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = np.bytes_(fmt.encode())
        f.attrs["format_version"] = 2
        if how == "external storage":
            f.create_dataset(text, shape=(16,), dtype=np.uint8, external=[(str(fifo), 0, 16)])
        elif how == "external link":
            f[text] = h5py.ExternalLink(str(fifo), "/text")
        else:
            layout = h5py.VirtualLayout(shape=(16,), dtype=np.uint8)
            layout[:] = h5py.VirtualSource(str(fifo), "text", shape=(16,))
            f.create_virtual_dataset(text, layout)
    return path


@pytest.mark.parametrize("how", ["external storage", "external link", "virtual dataset"])
def test_map_naming_another_file_is_refused_without_opening_it(tmp_path, how):
    path = _hdf5_naming_a_fifo(tmp_path, ".rmap", "baseplace-reachability-map", "grid", how)
    assert_refused("map", path, "refused" if how != "external link" else "ExternalLink",
                   ["reach", "--map", str(path), "--target", "0.6 0 0.8 0 0 0", "--base", "0 0 0"],
                   timeout=20)  # fmt: skip


def test_surface_map_with_external_storage_is_refused_without_opening_it(tmp_path):
    path = _hdf5_naming_a_fifo(tmp_path, ".smap", "baseplace-surface-map", "meta", "external storage")
    result = probe("smap", path, timeout=20)
    assert str(result["outcome"]).startswith("error: ") and "external" in str(result["outcome"]), result


def test_terrain_cache_entry_with_external_storage_is_not_read(tmp_path):
    # the cache reads every array through read_array; opening the FIFO would block, so in a subprocess
    path = _hdf5_naming_a_fifo(tmp_path, ".h5", "baseplace-terrain", "labels", "external storage")
    script = (
        "import sys, h5py; from pathlib import Path; from baseplace.h5files import read_array\n"
        "from baseplace.errors import InputError\n"
        "with h5py.File(sys.argv[1], 'r') as f:\n"
        "    try: read_array(f, 'labels', Path(sys.argv[1])); print('read')\n"
        "    except InputError as exc: print('error: ' + str(exc))\n"
    )
    proc = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True,
                          timeout=20, env=ENV)  # fmt: skip
    assert proc.stdout.startswith("error: ") and "external files" in proc.stdout, proc.stdout + proc.stderr


def test_map_cache_compression_check_follows_no_link(tmp_path):
    # the default-map cache asks whether a cached map is compressed before it loads it
    path = _hdf5_naming_a_fifo(tmp_path, ".rmap", "baseplace-reachability-map", "cells", "external link")
    script = "import sys; from baseplace.reachability.storage import is_compressed; print(is_compressed(sys.argv[1]))"
    proc = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True,
                          timeout=20, env=ENV)  # fmt: skip
    assert proc.stdout.strip() == "False", proc.stdout + proc.stderr
