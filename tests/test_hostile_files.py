"""Tiny hostile files (issue 15): each is refused in under 2 s and 200 MB, before allocating.

The memory oracle is the kernel's count of the process's resident memory: each load runs in a
fresh subprocess that notes its resident set after the imports, loads the file, and reports its
peak (``VmHWM``) minus that baseline, so allocations in C (HDF5, OpenCV) count as well as numpy's.
The CLI is run on the same files for exit 2 with one line.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import run_cli as cli  # the CLI's verdict, in this process; a load's memory: probe

SRC = str(Path(__file__).resolve().parents[1] / "src")
LIMIT_MB = 200.0
LIMIT_S = 2.0

_PROBE = """
import json, sys, time, traceback
from pathlib import Path
import baseplace.reachability.storage, baseplace.terrain.io, baseplace.world.occupancy
import baseplace.placement.surface_storage, baseplace.reachability.checkpoint
import h5py, numpy, cv2, PIL.Image, pypcd4, plyfile

def rss(field):
    for line in open("/proc/self/status"):
        if line.startswith(field):
            return int(line.split()[1]) / 1024.0
base = rss("VmRSS")
kind, path = sys.argv[1], sys.argv[2]
from baseplace.errors import InputError
load = {
    "map": lambda p: baseplace.reachability.storage.load_map(p),
    "cloud": lambda p: baseplace.terrain.io.load_cloud(p),
    "occupancy": lambda p: baseplace.world.occupancy.load_occupancy(p),
    "smap": lambda p: baseplace.placement.surface_storage.load_surface_map(p),
}[kind]
t0 = time.perf_counter()
try:
    load(path)
    outcome = "loaded"
except InputError as exc:
    outcome = "error: " + str(exc)
except BaseException as exc:
    outcome = "crash: " + "".join(traceback.format_exception_only(type(exc), exc))
elapsed = time.perf_counter() - t0
print(json.dumps({"outcome": outcome, "seconds": elapsed, "peak_mb": rss("VmHWM") - base}))
"""


def probe(kind: str, path: Path, **env: str) -> dict[str, object]:
    """Load ``path`` as ``kind`` in a fresh process (``env`` added to its environment): outcome, seconds, peak_mb."""
    proc = subprocess.run([sys.executable, "-c", _PROBE, kind, str(path)], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": SRC, **env})  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def assert_refused(kind: str, path: Path, fragment: str, cli_args: list[str]) -> None:
    result = probe(kind, path)
    assert str(result["outcome"]).startswith("error: "), result
    assert fragment in str(result["outcome"]), result
    assert float(result["seconds"]) < LIMIT_S, result  # type: ignore[arg-type]
    assert float(result["peak_mb"]) < LIMIT_MB, result  # type: ignore[arg-type]
    proc = cli(*cli_args)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and len(lines[0]) < 1000, proc.stderr[-2000:]
    assert fragment in lines[0], lines[0]  # the CLI refused the file, not its arguments


# --- the files -----------------------------------------------------------------------------------


def _small_map(tiago_map, path: Path, shape: tuple[int, int, int] | None = None) -> None:
    from baseplace.reachability.grid import SE3Grid
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.reachability.storage import save_map

    g = tiago_map.grid
    grid = g if shape is None else SE3Grid(g.origin, g.voxel_size, shape, g.nside, g.n_twist)
    keep = slice(0, 50)
    save_map(ReachabilityMap(grid, tiago_map.cells[keep], tiago_map.counts[keep], tiago_map.info), path)


def test_map_declaring_unwritten_huge_datasets(tmp_path, tiago_map):
    path = tmp_path / "bomb.rmap"
    _small_map(tiago_map, path)
    with h5py.File(path, "a") as f:  # replace the arrays by huge datasets never written
        for name, dtype in (("cells", np.int64), ("counts", np.uint32)):
            del f[name]
            f.create_dataset(name, shape=(4 * 10**9,), dtype=dtype, chunks=(2**20,), compression="gzip")
    assert path.stat().st_size < 20_000
    assert_refused("map", path, "can hold",
                   ["reach", "--map", str(path), "--target", "0.6 0 0.8 0 0 0", "--base", "0 0 0"])  # fmt: skip


def test_map_with_valid_checksum_and_huge_grid(tmp_path, tiago_map):
    path = tmp_path / "huge_grid.rmap"
    _small_map(tiago_map, path, (2000, 2000, 2000))
    assert path.stat().st_size < 20_000
    assert_refused("map", path, "beyond the limits",
                   ["reach", "--map", str(path), "--target", "0.6 0 0.8 0 0 0", "--base", "0 0 0"])  # fmt: skip


def test_huge_grid_checked_before_a_query_allocates(tiago_map):
    from baseplace.errors import InputError
    from baseplace.reachability.grid import SE3Grid
    from baseplace.reachability.rmap import ReachabilityMap

    g = tiago_map.grid
    huge = SE3Grid(g.origin, g.voxel_size, (5000, 5000, 5000), g.nside, g.n_twist)
    rmap = ReachabilityMap(huge, tiago_map.cells[:10], tiago_map.counts[:10], tiago_map.info)
    with pytest.raises(InputError, match="over the limit"):
        rmap.reachability(np.eye(4))


PCD_HEADER = (
    "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1000000000\n"
    "WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA binary\n"
)


def test_182_byte_pcd_with_a_huge_count(tmp_path):
    path = tmp_path / "count.pcd"
    data = PCD_HEADER.encode()
    path.write_bytes(data + b"\0" * (182 - len(data)))
    assert path.stat().st_size == 182
    assert_refused("cloud", path, "can hold", ["segment", str(path)])


@pytest.mark.parametrize("fmt", ["binary", "ascii", "binary_compressed"])
def test_pcd_declaring_more_points_than_its_bytes(tmp_path, fmt):
    path = tmp_path / "points.pcd"
    header = PCD_HEADER.replace("COUNT 1 1 1000000000", "COUNT 1 1 1").replace("WIDTH 1", "WIDTH 500000000")
    header = header.replace("POINTS 1", "POINTS 500000000").replace("DATA binary", f"DATA {fmt}")
    path.write_bytes(header.encode() + b"\0" * 64)
    assert_refused("cloud", path, "can hold", ["segment", str(path)])


def test_ply_and_npy_declaring_huge_sizes(tmp_path):
    ply = tmp_path / "v.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\n"
                    b"property float x\nproperty float y\nproperty float z\nend_header\n" + b"\0" * 24)  # fmt: skip
    assert_refused("cloud", ply, "can hold", ["segment", str(ply)])
    npy = tmp_path / "v.npy"
    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (3000000000, 3), }"
    header += b" " * (117 - len(header)) + b"\n"
    npy.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + b"\0" * 48)
    assert_refused("cloud", npy, "can hold", ["segment", str(npy)])


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return (
        struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


@pytest.mark.parametrize("side,fragment", [(12_000, "can hold"), (60_000, "more pixels than any map")])
def test_small_png_occupancy_image_with_huge_dimensions(tmp_path, side, fragment):
    width = height = side
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)  # 8-bit grey
    rows = zlib.compress(b"\0" * (width + 1) * 64, 9)  # 64 rows of a 144 M or 3.6 G pixel image
    png = (
        b"\x89PNG\r\n\x1a\n"
        + _png_chunk(b"IHDR", ihdr)
        + _png_chunk(b"IDAT", rows)
        + _png_chunk(b"IEND", b"")
    )
    (tmp_path / "huge.png").write_bytes(png)
    assert len(png) < 62_000
    yaml = tmp_path / "huge.yaml"
    yaml.write_text("image: huge.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    assert_refused("occupancy", yaml, fragment, ["occupancy", str(yaml)])


def test_long_image_name_gives_one_short_line(tmp_path):
    yaml = tmp_path / "long.yaml"
    yaml.write_text(f"image: {'a' * 5_000_000}.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    t0 = time.perf_counter()
    proc = cli("occupancy", str(yaml))
    assert proc.returncode == 2 and len(proc.stderr) < 1000, proc.stderr[:1000]
    assert "the limit is 65536 (64 KiB)" in proc.stderr, proc.stderr[:1000]  # refused before PyYAML parses it
    assert time.perf_counter() - t0 < 10
    # a name that fits the YAML's limit but no file system's
    yaml.write_text(f"image: {'a' * 5000}.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    proc = cli("occupancy", str(yaml))
    assert proc.returncode == 2 and "'image' path is 5004 bytes long" in proc.stderr, proc.stderr[:1000]


def test_a_file_name_longer_than_the_os_takes_is_one_line_for_every_reader(tmp_path):
    """A 300-byte name (over the 255 bytes a component may have) given to readers that do not check it first."""
    long = str(tmp_path / ("a" * 300))
    for args in (["occupancy", f"{long}.yaml"], ["reach", "--map", f"{long}.rmap", "--target", "1 0.5 0.9 0 0 0",
                 "--base", "0.2 0.6 1.05"], ["robot", "check", f"{long}.toml"], ["view", f"{long}.json"],
                 ["surface-sample", "--map", f"{long}.smap"]):  # fmt: skip
        proc = cli(*args)
        assert proc.returncode == 2, (args[0], proc.stderr[-2000:])
        message = proc.stderr[-2000:]
        assert proc.stderr.count("\n") == 1 and "the file name is too long" in message, message


@pytest.mark.parametrize(
    "field,value", [("height", float("nan")), ("height", 1e300), ("tcp_height", float("inf"))]
)
def test_surface_map_with_bad_numbers(tmp_path, field, value):
    from baseplace.h5files import digest, read_text, short_text, write_text
    from baseplace.placement.surface_map import SurfaceMap
    from baseplace.placement.surface_storage import save_surface_map

    polygon = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    values = np.zeros((4, 5, 5), dtype=np.float32)
    values[0, 1, 1] = 0.5
    smap = SurfaceMap(values, (-1.0, -1.0), 0.1, polygon, 0.7, "tiago", ("arm",), "any", None, 1.0)
    path = tmp_path / "bad.smap"
    save_surface_map(smap, path)
    with h5py.File(path, "a") as f:  # rewrite the meta with the bad number and a valid checksum
        meta = json.loads(read_text(f, "meta"))
        meta[field] = value
        del f["meta"]
        text = write_text(f, "meta", json.dumps(meta))
        f.attrs["sha256"] = short_text(digest(text, f["index"][()], f["value"][()]))
    result = probe("smap", path)
    assert str(result["outcome"]).startswith("error: "), result


def _robot_file(path):
    from baseplace.robots.spec import load_spec

    return load_spec(path)


def _map_yaml(path):
    from baseplace.world.occupancy import load_occupancy

    return load_occupancy(path)


def _camera_info(path):
    from baseplace.perception.rgbd import parse_intrinsics

    return parse_intrinsics(str(path))


@pytest.mark.parametrize(
    ("suffix", "limit", "read"),
    [(".yaml", 1 << 20, _robot_file), (".toml", 1 << 20, _robot_file), (".yaml", 64 << 10, _map_yaml),
     (".yaml", 1 << 20, _camera_info)],
    ids=["robot-yaml", "robot-toml", "map-yaml", "camera-info"],
)  # fmt: skip
def test_small_documents_over_their_limit_are_refused_before_the_parser(
    tmp_path, monkeypatch, suffix, limit, read
):
    """Robot files, map YAMLs and CameraInfo files: the size is checked before PyYAML or tomllib sees a byte."""
    import tomllib
    import yaml

    from baseplace.errors import InputError

    def parser(*_):
        raise AssertionError("the parser was called")

    monkeypatch.setattr(yaml, "safe_load", parser)
    monkeypatch.setattr(tomllib, "loads", parser)
    path = tmp_path / f"big{suffix}"
    path.write_bytes(b"#" * (limit + 1))
    with pytest.raises(InputError, match=rf"big\{suffix} is {limit + 1} bytes; the limit is {limit} "):
        read(path)
    path.write_bytes(b"name: \xff\xfe\n")  # not UTF-8: one line, whatever the reader
    with pytest.raises(InputError, match=rf"big\{suffix}: not UTF-8 text"):
        read(path)
