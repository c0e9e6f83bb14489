"""Hostile ROS recordings (issue 28): clouds, grids, chunks and tf bounded before they are decoded.

Each bag is read in a fresh subprocess that reports its peak resident memory (``VmHWM``, as
``tests/test_hostile_files.py`` measures it) under ``BASEPLACE_MAX_MEMORY_MB``; the CLI and the
service's upload path are run on the issue's bag too. tf recording is timed at 20 k and 200 k
transforms in the same test: linear recording takes about 10x as long, the quadratic one 40x.
"""

from __future__ import annotations

import json
import os
import re
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.io.bag import read_bag
from baseplace.io.bag_writer import CloudRecord, GridRecord, TfRecord, write_input_bag
from baseplace.io.messages import POINTCLOUD2, TF_MESSAGE, cloud_msg, header, tf_msg
from baseplace.world.occupancy import OccupancyGrid
from conftest import run_cli

SRC = str(Path(__file__).resolve().parents[1] / "src")
T0 = 10**9

_PROBE = """
import json, sys, time, traceback

def rss(field):
    for line in open("/proc/self/status"):
        if line.startswith(field):
            return int(line.split()[1]) / 1024.0

import numpy, rosbags.highlevel, rosbags.rosbag1, rosbags.rosbag2, scipy.spatial.transform
from baseplace.errors import InputError
from baseplace.io.bag import read_bag
kind, path, args = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
if kind == "service":
    from baseplace.serve.state import ServeSettings, ServiceState
    state = ServiceState(ServeSettings(warm_up=False, robots=()))
    data = open(path, "rb").read()
base = rss("VmRSS")
t0 = time.perf_counter()
try:
    if kind == "service":
        state.add_scene(data, "bag", args)
    else:
        read_bag(path, args["cloud_topics"], args.get("map_topic"), "map", args.get("clouds", "last"))
    outcome = "loaded"
except InputError as exc:
    outcome = "error: " + str(exc)
except BaseException as exc:
    outcome = "crash: " + "".join(traceback.format_exception_only(type(exc), exc))
result = {"outcome": outcome, "seconds": time.perf_counter() - t0, "peak_mb": rss("VmHWM"),
          "growth_mb": rss("VmHWM") - base}
if kind == "service" and len(sys.argv) > 4:  # an honest upload right after, in its normal time
    t0 = time.perf_counter()
    scene = state.add_scene(open(sys.argv[4], "rb").read(), "bag", {"cloud_topics": ["/points"]})
    result["honest_points"], result["honest_seconds"] = scene.points, time.perf_counter() - t0
print(json.dumps(result))
"""


def probe(kind: str, path: Path, cap_mb: int, args: dict[str, object], *extra: str) -> dict[str, object]:
    env = {**os.environ, "PYTHONPATH": SRC, "BASEPLACE_MAX_MEMORY_MB": str(cap_mb)}
    proc = subprocess.run([sys.executable, "-c", _PROBE, kind, str(path), json.dumps(args), *extra],
                          capture_output=True, text=True, timeout=600, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _ros1_store():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MESSAGE))
    return ts


def cloud_bag(path: Path, n: int, step: int, offsets: tuple[int, int, int], compression: str = "bz2") -> Path:
    """A ROS 1 bag of one PointCloud2 of ``n`` zero points, ``step`` bytes each, x y z at ``offsets``."""
    from rosbags.rosbag1 import Writer

    ts = _ros1_store()
    g = ts.types
    fields = [g["sensor_msgs/msg/PointField"](name=c, offset=o, datatype=7, count=1)
              for c, o in zip("xyz", offsets, strict=True)]  # fmt: skip
    msg = g[POINTCLOUD2](header=header(ts, "map", T0), height=1, width=n, fields=fields, is_bigendian=False,
                         point_step=step, row_step=step * n, data=np.zeros(step * n, np.uint8), is_dense=False)  # fmt: skip
    writer = Writer(path)
    if compression != "none":
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        writer.write(conn, T0, ts.serialize_ros1(msg, POINTCLOUD2))
    return path


def small_bag(path: Path, fmt: str = "ros1", n: int = 2000) -> Path:
    points = np.random.default_rng(0).uniform(-1, 1, (n, 3))
    points[:, 2] = 0.0  # a floor
    write_input_bag(path, fmt, clouds=[CloudRecord("/points", "map", T0, points)])
    return path


def cli(*args: str, cap_mb: int) -> subprocess.CompletedProcess[str]:
    """The CLI's verdict under the cap; its memory is measured by ``probe``, in a fresh process."""
    return run_cli(*args, env={"BASEPLACE_MAX_MEMORY_MB": str(cap_mb)})


# --- clouds and chunks -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def issue_bag(tmp_path_factory) -> Path:
    """The issue's bag: 6 kB of bz2 declaring 20 M points of 4 bytes, x, y and z all at offset 0."""
    path = cloud_bag(tmp_path_factory.mktemp("issue") / "cloud.bag", 20_000_000, 4, (0, 0, 0))
    assert path.stat().st_size < 8000
    return path


def test_issue_bag_refused_under_the_cap(issue_bag):
    result = probe("bag", issue_bag, 512, {"cloud_topics": ["/points"]})
    assert str(result["outcome"]).startswith("error: ") and "overlap" in str(result["outcome"]), result
    assert float(result["peak_mb"]) < 512, result  # type: ignore[arg-type]
    proc = cli("segment", "--bag", str(issue_bag), "--cloud-topic", "/points", cap_mb=512)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    assert "x, y, z overlap" in lines[0]


def test_issue_bag_through_the_service_then_an_honest_one(issue_bag, tmp_path):
    honest = small_bag(tmp_path / "honest.bag")
    result = probe("service", issue_bag, 512, {"cloud_topics": ["/points"]}, str(honest))
    assert str(result["outcome"]).startswith("error: "), result
    assert float(result["peak_mb"]) < 512, result  # type: ignore[arg-type]
    assert result["honest_points"] == 2000 and float(result["honest_seconds"]) < 30, result  # type: ignore[arg-type]


def test_cloud_of_honest_layout_beyond_the_cap(tmp_path):
    # 2 M points of 12 bytes: 24 MB of data, 96 MB once read; lz4 chunks
    path = cloud_bag(tmp_path / "big.bag", 2_000_000, 12, (0, 4, 8), "lz4")
    result = probe("bag", path, 64, {"cloud_topics": ["/points"]})
    assert str(result["outcome"]).startswith("error: ") and "over the limit of 67 MB" in str(
        result["outcome"]
    ), result
    assert float(result["growth_mb"]) < 64, result  # type: ignore[arg-type]


def test_chunk_inflating_beyond_the_cap(tmp_path):
    # 24 MB of cloud in one bz2 chunk of a few kB; the cap is 16 MB: refused before it is inflated
    path = cloud_bag(tmp_path / "bomb.bag", 2_000_000, 12, (0, 4, 8))
    result = probe("bag", path, 16, {"cloud_topics": ["/points"]})
    assert "decompressed chunk would take 24" in str(result["outcome"]), result
    assert float(result["growth_mb"]) < 16, result  # type: ignore[arg-type]


def test_mcap_chunks_inflating_beyond_the_cap(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    msg = cloud_msg(ts, np.zeros((2_000_000, 3)), "map", T0)
    path = tmp_path / "bomb_mcap"
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        writer.write(conn, T0, ts.serialize_cdr(msg, POINTCLOUD2))
    (mcap,) = path.glob("*.mcap")
    assert mcap.stat().st_size < 100_000
    result = probe("bag", mcap, 16, {"cloud_topics": ["/points"]})
    assert "decompressed chunk" in str(result["outcome"]) and "over the limit" in str(result["outcome"]), (
        result
    )
    assert float(result["growth_mb"]) < 16, result  # type: ignore[arg-type]


def test_chunk_inflating_beyond_its_declared_size(tmp_path):
    path = small_bag(tmp_path / "lie.bag", n=20_000)
    raw = path.read_bytes()
    field = b"\x09\x00\x00\x00size="  # the chunk header's uncompressed size
    at = raw.index(field) + len(field)
    path.unlink()
    from rosbags.rosbag1 import Writer  # the same bag, bz2 compressed, its chunk declaring 100 bytes

    ts = _ros1_store()
    points = np.random.default_rng(0).uniform(-1, 1, (20_000, 3))
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.BZ2)
    with writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        writer.write(conn, T0, ts.serialize_ros1(cloud_msg(ts, points, "map", T0), POINTCLOUD2))
    raw = path.read_bytes()
    at = raw.index(field) + len(field)
    path.write_bytes(raw[:at] + struct.pack("<I", 100) + raw[at + 4 :])
    with pytest.raises(InputError, match="inflates beyond the 100 bytes its header declares"):
        read_bag(path, ["/points"])


def test_all_clouds_bounded_together(tmp_path, monkeypatch):
    # two clouds of 800 k points, 38 MB each once read: each fits a 64 MB cap, both do not
    points = np.zeros((800_000, 3))
    clouds = [CloudRecord("/points", "map", T0 + k, points) for k in range(2)]
    write_input_bag(tmp_path / "two", "mcap", clouds=clouds)
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "64")
    assert len(read_bag(tmp_path / "two", ["/points"], clouds="last").clouds) == 1
    with pytest.raises(InputError, match="1600000 points of all clouds would take"):
        read_bag(tmp_path / "two", ["/points"], clouds="all")


def test_grid_beyond_the_cap(tmp_path, monkeypatch):
    grid = OccupancyGrid(np.zeros((2500, 4000), dtype=np.int8), 0.05)  # 10 M cells
    write_input_bag(tmp_path / "grid", "mcap", grids=[GridRecord("/map", "map", T0, grid)])
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "64")
    with pytest.raises(
        InputError, match=r"occupancy grid of 4000 x 2500 cells would take 100 MB, over the limit"
    ):
        read_bag(tmp_path / "grid", map_topic="/map")


# --- tf ------------------------------------------------------------------------------------------


def tf_bag(path: Path, n: int, compress: bool = True) -> Path:
    """A ROS 1 bag (bz2: ``compress``) of one small cloud and one /tf message of ``n`` identical transforms."""
    from rosbags.rosbag1 import Writer

    ts = _ros1_store()
    one = ts.serialize_ros1(tf_msg(ts, [("map", "cam", np.eye(4))], T0), TF_MESSAGE)
    raw = struct.pack("<I", n) + bytes(one[4:]) * n  # TFMessage: a count, then the transforms
    cloud = ts.serialize_ros1(
        cloud_msg(ts, np.random.default_rng(0).random((100, 3)), "cam", T0), POINTCLOUD2
    )
    writer = Writer(path)
    if compress:
        writer.set_compression(Writer.CompressionFormat.BZ2)
    with writer:
        points = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        tf = writer.add_connection("/tf", TF_MESSAGE, typestore=ts)
        writer.write(points, T0, cloud)
        writer.write(tf, T0, raw)
    return path


def test_tf_recording_is_linear(tmp_path):
    # Ten times the transforms must cost about ten times the time, not a hundred (a quadratic
    # insert). The best of three reads per size, and a bound at the geometric middle of 10x and
    # 100x (32x): one read at 20x was seen on a loaded CI machine (0.17 s vs 3.59 s).
    seconds, scenes = {}, {}
    for n in (10_000, 100_000):
        path = tf_bag(tmp_path / f"tf{n}.bag", n)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            scenes[n] = read_bag(path, ["/points"])
            times.append(time.perf_counter() - t0)
        seconds[n] = min(times)
    assert path.stat().st_size < 12_000
    print(f"tf recording: 10 k {seconds[10_000]:.2f} s, 100 k {seconds[100_000]:.2f} s")
    assert seconds[100_000] < 32 * seconds[10_000], seconds
    for n, scene in scenes.items():
        assert len(scene.clouds[0].points) == 100
        assert np.allclose(scene.tf.lookup("map", "cam", T0), np.eye(4))
        assert scene.tf.count == n


def test_tf_transforms_beyond_the_limit(tmp_path):
    path = tf_bag(tmp_path / "tf_limit.bag", 1_000_001, compress=False)  # 82 MB
    result = probe("bag", path, 4096, {"cloud_topics": ["/points"]})
    assert "more than 1000000 transforms on /tf and /tf_static; the limit is 1000000" in str(
        result["outcome"]
    )
    assert float(result["seconds"]) < 10, result  # type: ignore[arg-type]


def test_tf_message_count_read_before_decoding(tmp_path):
    from baseplace.io.bag import _open
    from baseplace.io.bag_limits import tf_message_count

    edges = [("map", f"f{k}", np.eye(4)) for k in range(3)]
    for fmt in ("mcap", "ros1"):
        path = tmp_path / ("tf.bag" if fmt == "ros1" else "tf_mcap")
        write_input_bag(path, fmt, tf=[TfRecord(p, c, T0 + k, T) for k, (p, c, T) in enumerate(edges)])
        reader = _open(path)
        try:
            for conn, _, raw in reader.messages():
                assert tf_message_count(raw, reader.is2) == len(
                    reader.deserialize(raw, conn.msgtype).transforms
                )
        finally:
            reader.close()


def test_tf_out_of_order_and_repeated_stamps():
    from baseplace.io.tf import TfTree

    tree = TfTree()
    for s in (3, 1, 2, 2, 0):
        tree.add("map", "base", s * 10**9, [float(s), 0, 0], [0, 0, 0, 1], static=False)
    T = tree.lookup("map", "base", int(1.5 * 10**9))
    assert T[0, 3] == pytest.approx(1.5)
    bad = re.escape("invalid translation or quaternion")
    with pytest.raises(InputError, match=bad):
        tree.add("map", "base", 0, [np.nan, 0, 0], [0, 0, 0, 1], static=False)


@pytest.mark.parametrize("compression", ["bz2", "lz4", "zstd"])
def test_honest_compressed_bags_read_through_the_bounded_decompressors(tmp_path, compression):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    points = np.random.default_rng(1).uniform(-1, 1, (300_000, 3)).astype(np.float32)  # 3.6 MB: 4 chunks
    if compression == "zstd":
        ts = get_typestore(Stores.ROS2_HUMBLE)
        path = tmp_path / "rec"
        writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        serialize = ts.serialize_cdr
    else:
        ts = _ros1_store()
        path = tmp_path / "rec.bag"
        writer = Writer1(path)
        writer.set_compression(getattr(Writer1.CompressionFormat, compression.upper()))
        serialize = ts.serialize_ros1
    with writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        for k in range(4):
            writer.write(conn, T0 + k, serialize(cloud_msg(ts, points + k, "map", T0 + k), POINTCLOUD2))
    scene = read_bag(next(path.glob("*.mcap")) if path.is_dir() else path, ["/points"], clouds="all")
    assert len(scene.clouds) == 4
    for k, c in enumerate(scene.clouds):
        assert np.array_equal(c.points, (points + k).astype(np.float64))


def _zstd_rosbag2(path: Path, mode: str, n_points: int) -> Path:
    """A rosbag2 directory (sqlite3) of one zero cloud, compressed per message or per file with zstd."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    writer = Writer(path, version=9)
    writer.set_compression(getattr(CompressionMode, mode), CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/points", POINTCLOUD2, typestore=ts)
        writer.write(
            conn, T0, ts.serialize_cdr(cloud_msg(ts, np.zeros((n_points, 3)), "map", T0), POINTCLOUD2)
        )
    return path


def test_rosbag2_message_compression_bounded_by_the_cap(tmp_path):
    # 24 MB of cloud in one zstd message of a few kB; the cap is 16 MB: refused while it inflates
    path = _zstd_rosbag2(tmp_path / "bomb", "MESSAGE", 2_000_000)
    assert sum(f.stat().st_size for f in path.iterdir()) < 200_000
    result = probe("bag", path, 16, {"cloud_topics": ["/points"]})
    assert str(result["outcome"]).startswith("error: "), result
    assert "zstd message" in str(result["outcome"]) and "over the limit" in str(result["outcome"]), result
    assert float(result["growth_mb"]) < 16, result  # type: ignore[arg-type]


def test_rosbag2_message_of_undeclared_size_inflated_up_to_the_cap(tmp_path):
    # a zstd frame need not declare its size: then it is inflated, and refused, at the cap
    import sqlite3

    from baseplace.io.bag_limits import _zstd_module

    path = _zstd_rosbag2(tmp_path / "bomb", "MESSAGE", 1000)
    c = _zstd_module().ZstdCompressor()
    streamed = b"".join(c.compress(b"\0" * 2**20) for _ in range(40)) + c.flush()  # 40 MB, no size declared
    (db,) = path.glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = ?", (streamed,))
    result = probe("bag", path, 16, {"cloud_topics": ["/points"]})
    assert "zstd message" in str(result["outcome"]) and "over the limit of 17 MB" in str(result["outcome"]), (
        result
    )
    assert float(result["growth_mb"]) < 2 * 16 + 8, result  # type: ignore[arg-type]  # the cap, its copy, zstd's window


def test_rosbag2_file_compression_bounded_by_the_temporary_folder(tmp_path, monkeypatch):
    # rosbags inflates a file-compressed bag's files whole into a temporary folder first
    from baseplace.io import bag_limits

    path = _zstd_rosbag2(tmp_path / "bomb", "FILE", 2_000_000)
    monkeypatch.setattr(bag_limits, "temporary_space", lambda: 8_000_000)
    with pytest.raises(InputError, match=r"inflates beyond the 8000000 bytes free .* temporary folder"):
        read_bag(path, ["/points"])
    monkeypatch.undo()
    assert read_bag(path, ["/points"]).clouds[0].points.shape == (2_000_000, 3)


@pytest.mark.parametrize("mode", ["MESSAGE", "FILE"])
def test_honest_rosbag2_compressed_bags_read_through_the_bounded_decompressors(tmp_path, mode):
    path = _zstd_rosbag2(tmp_path / "rec", mode, 1000)
    assert read_bag(path, ["/points"]).clouds[0].points.shape == (1000, 3)


def test_a_zstd_message_of_several_frames_inflates_whole():
    # rosbags inflates a message with zstd.decompress, which reads every frame; so must the bounded one
    from baseplace.io.bag_limits import _BoundedZstd, _zstd_module

    zstd = _zstd_module()
    c = zstd.ZstdCompressor()
    undeclared = c.compress(b"ef" * 700) + c.flush()
    data = zstd.compress(b"ab" * 1000) + zstd.compress(b"cd" * 500) + undeclared
    assert _BoundedZstd.decompress(data) == zstd.decompress(data) == b"ab" * 1000 + b"cd" * 500 + b"ef" * 700
