"""Fuzz every loader and the pose math on a CI budget (issue 9.3).

Each target of ``fuzz_cases.TARGETS`` runs ``ci_examples`` derandomized hypothesis cases: every
case must load or raise a clean one-line BaseplaceError (loaders), or satisfy its property (pose
math). ``bench/fuzz.py`` runs the same strategies on >= 10,000 cases per target.

A crash matching an open bug of ``fuzz_cases.KNOWN_BUGS`` is tolerated here; each such bug has a
strict-xfail reproducer below. When a fix lands, the reproducer XPASSes and fails the suite: move
the entry to ``fuzz_cases.FIXED_BUGS``, which makes the reproducer a plain regression test (the
reproducers of the bugs already fixed are regression tests now). The reproducer of the HDF5 hang
runs in a subprocess.
"""

from __future__ import annotations

import faulthandler
import io
import json
import math
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import h5py
import numpy as np
import pytest
import yaml
from hypothesis import given, settings

import fuzz_cases as fc
from baseplace.errors import BaseplaceError, InputError
from baseplace.h5files import digest

F = TypeVar("F", bound=Callable[..., object])


@pytest.mark.parametrize("name", list(fc.TARGETS))
def test_fuzz_target(name: str, tmp_path: Path) -> None:
    target = fc.TARGETS[name]
    fc.prepare(name)

    @settings(fc.CI_SETTINGS, max_examples=target.ci_examples)
    @given(target.strategy)
    def check(case: object) -> None:
        result = fc.run_case(target, case, tmp_path / "case", time_limit=10.0)
        if result.outcome in (fc.LOADED, fc.CLEAN) or fc.known_bug(name, result):
            return
        raise AssertionError(f"{name}: {result.outcome}: {result.signature}: {result.message}")

    # a hang inside native code (HDF5 holds the GIL) escapes the per-case alarm: dump the stacks and
    # end the run rather than hang CI forever
    faulthandler.dump_traceback_later(600, exit=True)
    try:
        check()
    finally:
        faulthandler.cancel_dump_traceback_later()


def test_mutations_are_deterministic_and_bounded() -> None:
    data = bytes(range(256)) * 4
    ops = [
        ("flip", 5000, 1),
        ("insert", 3, b"xy"),
        ("delete", 10, 4),
        ("overwrite", 0, b"Z"),
        ("truncate", 0.5),
    ]
    assert fc.apply_byte_ops(data, ops) == fc.apply_byte_ops(data, ops)
    assert fc.apply_byte_ops(b"", ops) == b""
    lines = ["VERSION 0.7", "FIELDS x y z", "DATA ascii"]
    assert fc.apply_line_ops(lines, [("replace", 4, 1, "nan"), ("delete", 0)]) == [
        "FIELDS nan y z",
        "DATA ascii",
    ]
    assert fc.apply_line_ops([], [("delete", 3), ("insert", 9, "a")]) == ["a"]


def test_outcomes_are_classified(tmp_path: Path) -> None:
    def target(run):  # a loader stub
        return fc.Target("stub", fc.st.none(), run)

    def clean(case, workdir):
        raise InputError("bad file")

    def multi_line(case, workdir):
        raise InputError("bad\nfile")

    def crash(case, workdir):
        raise KeyError("x")

    def slow(case, workdir):
        while True:
            pass

    assert fc.run_case(target(lambda c, w: None), None, tmp_path).outcome == fc.LOADED
    assert fc.run_case(target(clean), None, tmp_path).outcome == fc.CLEAN
    assert fc.run_case(target(multi_line), None, tmp_path).outcome == fc.CRASH
    result = fc.run_case(target(crash), None, tmp_path)
    assert result.outcome == fc.CRASH and result.signature.startswith("KeyError @ ")
    assert fc.run_case(target(slow), None, tmp_path, time_limit=0.2).outcome == fc.HANG


# --- reproducers of the bugs this fuzzing found: open ones (fuzz_cases.KNOWN_BUGS) are strict xfails,
# fixed ones (fuzz_cases.FIXED_BUGS) plain regression tests ---


def _bug(bug_id: str) -> Callable[[F], F]:
    """Strict xfail for an open bug; nothing for a fixed one (the reproducer is a regression test)."""
    bug = next((b for b in fc.KNOWN_BUGS if b.id == bug_id), None)
    if bug is None:
        assert any(b.id == bug_id for b in fc.FIXED_BUGS), f"no bug {bug_id!r} in KNOWN_BUGS or FIXED_BUGS"
        return lambda test: test
    return pytest.mark.xfail(strict=True, reason=f"{bug.id}: {bug.reason}")


@_bug("transform-long-text")
def test_transform_long_inline_text_is_a_clean_error() -> None:
    from baseplace.terrain.io import load_transform

    inline = " ".join(["0.7071067811865476"] * 16)  # a 4x4 typed inline: 303 chars, one path component
    with pytest.raises(BaseplaceError, match="4x4 matrix goes in a file"):
        load_transform(inline)


@_bug("transform-tilde-user")
def test_transform_unknown_user_home_is_a_clean_error() -> None:
    from baseplace.terrain.io import load_transform

    with pytest.raises(BaseplaceError):
        load_transform("~no_such_user_fuzz 0 1")


@_bug("yaml-toml-deep-nesting")
@pytest.mark.parametrize("kind", ["occupancy", "robot.yaml", "robot.toml"])
def test_deeply_nested_yaml_or_toml_is_a_clean_error(kind: str, tmp_path: Path) -> None:
    from baseplace.robots.spec import load_spec
    from baseplace.world.occupancy import load_occupancy

    nested = "[" * 600 + "]" * 600
    with pytest.raises(BaseplaceError):
        if kind == "occupancy":
            (tmp_path / "map.yaml").write_text(f"image: {nested}\n")
            load_occupancy(tmp_path / "map.yaml")
        else:
            path = tmp_path / kind
            path.write_text(f"name = {nested}\n" if kind.endswith(".toml") else f"name: {nested}\n")
            load_spec(path)


@_bug("yaml-alias-repr")
@pytest.mark.parametrize("kind", ["occupancy", "robot"])
def test_yaml_alias_bomb_stays_small(kind: str, tmp_path: Path) -> None:
    """A 400-byte YAML whose value is a 10**6-item aliased list: the message or name must stay short.

    Each further level costs 10x: level 8 (546 bytes) takes 39 s and builds a 522 MB message.
    """
    from baseplace.robots.spec import load_spec
    from baseplace.world.occupancy import load_occupancy

    if kind == "occupancy":
        text = yaml.safe_dump({**fc._GOOD_MAP, "image": "map.pgm"}).replace("image: map.pgm\n", "")
        (tmp_path / "map.yaml").write_text(text + fc.alias_bomb(6, "image"))
        with pytest.raises(BaseplaceError) as info:
            load_occupancy(tmp_path / "map.yaml")
        assert len(str(info.value)) < 2000
    else:
        good = {"urdf": str(fc.DATA / "planar3.urdf"), "base_frame": "base_link", "footprint": {"radius": 0.3},
                "arms": {"arm": {"joints": ["joint1"], "tcp_frame": "tool0"}}}  # fmt: skip
        (tmp_path / "r.yaml").write_text(yaml.safe_dump(good) + fc.alias_bomb(6, "name"))
        with pytest.raises(BaseplaceError):  # a name must be a string, not a list
            load_spec(tmp_path / "r.yaml")


def _rewrite(kind: str, tmp_path: Path, arrays: dict[str, np.ndarray] | None = None, **texts: str) -> Path:
    """The reference map of ``kind`` with JSON texts or datasets replaced and the checksum made valid
    again."""
    path = tmp_path / ("m.rmap" if kind == "rmap" else "s.h5")
    path.write_bytes(fc.reference_files()[kind])
    replace = {k: np.frombuffer(v.encode(), dtype=np.uint8) for k, v in texts.items()} | (arrays or {})
    with h5py.File(path, "a") as f:
        for key, value in replace.items():
            del f[key]
            f[key] = value
        parts = [f[k][()] for k in fc.TEXTS[kind]] + [f[k][()] for k in f if k not in fc.TEXTS[kind]]
        f.attrs["sha256"] = np.bytes_(digest(*parts).encode())
    return path


def _json_attr(kind: str, name: str, **changes: object) -> str:
    doc = json.loads(fc.reference_contents(kind)[1][name])
    doc.update(changes)
    return json.dumps(doc)


@_bug("rmap-attributes-unchecked")
@pytest.mark.parametrize(
    "attrs",
    [
        {"info": "extra key"},
        {"info": "no joint_names"},
        {"grid": "null"},
        {"grid": "voxel_size as text"},
        {"info": "deep"},
    ],
    ids=lambda a: next(iter(a.values())),
)
def test_map_with_odd_attributes_is_a_clean_error(attrs: dict[str, str], tmp_path: Path) -> None:
    from baseplace.reachability.storage import load_map

    ((key, what),) = attrs.items()
    if what == "extra key":
        value = _json_attr("rmap", "info", colour="red")
    elif what == "no joint_names":
        doc = json.loads(_json_attr("rmap", "info"))
        del doc["joint_names"]
        value = json.dumps(doc)
    elif what == "voxel_size as text":
        value = _json_attr("rmap", "grid", voxel_size="0.05")
    elif what == "deep":
        value = "[" * 100_000 + "]" * 100_000
    else:
        value = "null"
    with pytest.raises(BaseplaceError):
        load_map(_rewrite("rmap", tmp_path, **{key: value}))


@_bug("rmap-grid-unbounded")
def test_map_with_huge_nside_is_a_clean_error(tmp_path: Path) -> None:
    """nside 2**40 fails to allocate at once; nside 4096 would loop in Python for minutes."""
    from baseplace.reachability.storage import load_map

    with pytest.raises(BaseplaceError):
        load_map(_rewrite("rmap", tmp_path, grid=_json_attr("rmap", "grid", nside=2**40)))


@_bug("hdf5-global-heap-hang")
@pytest.mark.parametrize("kind", ["rmap", "smap", "checkpoint"])
def test_corrupt_global_heap_is_a_clean_error(kind: str, tmp_path: Path) -> None:
    """A file of format version 1, whose texts were variable-length strings in HDF5's global heap,
    with the heap collection's size field corrupt (4096 -> 40192, as one fuzzed byte did).

    HDF5 2.0 never returns from reading such a string, holding the GIL, so the loaders must not read
    it at all; run in a subprocess, since nothing in-process could stop the hang.
    """
    fmt = {"rmap": "baseplace-reachability-map", "smap": "baseplace-surface-map",
           "checkpoint": "baseplace-build-checkpoint"}[kind]  # fmt: skip
    path = tmp_path / "old.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = fmt
        f.attrs["format_version"] = 1
        f.attrs["meta"] = "{}"
        f.attrs["sha256"] = "0" * 64
    data = bytearray(path.read_bytes())
    heap = data.find(b"GCOL")
    assert heap > 0 and data[heap + 9] == 0x10  # the collection's size, 4096, little-endian
    data[heap + 9] ^= 0x8D
    path.write_bytes(bytes(data))
    call = {
        "rmap": "from baseplace.reachability.storage import load_map as load\nload(PATH)",
        "smap": "from baseplace.placement.surface_storage import load_surface_map as load\nload(PATH)",
        "checkpoint": "from baseplace.reachability.checkpoint import load_checkpoint as load\nload(PATH, None)",
    }
    code = (
        "from baseplace.errors import BaseplaceError\n"
        f"PATH = {str(path)!r}\ntry:\n    " + call[kind].replace("\n", "\n    ") + "\n"
        "except BaseplaceError as e:\n    print('clean:', e)\n"
    )  # fmt: skip
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"load of the {kind} did not return within 120 s") from None
    assert done.stdout.startswith("clean:") and "format version 1" in done.stdout, done.stderr[-500:]


@_bug("hdf5-runtime-error")
def test_map_with_corrupt_local_heap_is_a_clean_error(tmp_path: Path) -> None:
    """One flipped byte of the reference map (in the superblock's root group address): h5py itself
    raises RuntimeError, not OSError, when asked whether a dataset exists."""
    from baseplace.reachability.storage import load_map

    data = fc.apply_byte_ops(fc.reference_files()["rmap"], [("flip", 17, 0x56)])
    with pytest.raises(RuntimeError), h5py.File(io.BytesIO(data), "r") as f:
        _ = "manipulability" in f
    path = tmp_path / "corrupt.rmap"
    path.write_bytes(data)
    with pytest.raises(BaseplaceError, match="truncated or corrupt"):
        load_map(path)


@_bug("occupancy-mode-str")
def test_occupancy_alias_bomb_mode_stays_small(tmp_path: Path) -> None:
    """'mode' as a 400-byte alias bomb (10**6 items): str() of it makes a 5 MB message."""
    from baseplace.world.occupancy import load_occupancy

    (tmp_path / "map.yaml").write_text(
        yaml.safe_dump({**fc._GOOD_MAP, "image": "map.pgm"}) + fc.alias_bomb(6, "mode")
    )
    with pytest.raises(BaseplaceError) as info:
        load_occupancy(tmp_path / "map.yaml")
    assert len(str(info.value)) < 2000


@_bug("smap-meta-unchecked")
@pytest.mark.parametrize("change", ["no origin", "resolution as list", "huge shape"])
def test_surface_map_with_odd_meta_is_a_clean_error(change: str, tmp_path: Path) -> None:
    from baseplace.placement.surface_storage import load_surface_map

    doc = json.loads(_json_attr("smap", "meta"))
    if change == "no origin":
        del doc["origin"]
    elif change == "resolution as list":
        doc["resolution"] = [0.1]
    else:
        doc["shape"] = [100_000, 100_000, 100]  # 4 TB of float32
    with pytest.raises(BaseplaceError):
        load_surface_map(_rewrite("smap", tmp_path, meta=json.dumps(doc)))


@_bug("polygon-ragged-array")
@pytest.mark.parametrize("polygon", [[[0, 0], [1, 0], [0]], [["a", "b"]] * 3], ids=["ragged", "strings"])
def test_polygon_from_odd_arrays_is_a_clean_error(polygon: object) -> None:
    from baseplace.placement.surface_map import parse_polygon

    with pytest.raises(BaseplaceError):
        parse_polygon(polygon)


def test_reference_files_load(tmp_path: Path) -> None:
    """The fuzzed reference maps are real maps: unmutated, they load."""
    from baseplace.placement.surface_storage import load_surface_map
    from baseplace.reachability.storage import load_map

    (tmp_path / "m.rmap").write_bytes(fc.reference_files()["rmap"])
    (tmp_path / "s.h5").write_bytes(fc.reference_files()["smap"])
    assert load_map(tmp_path / "m.rmap").n_reached > 0
    assert load_surface_map(tmp_path / "s.h5").values.max() > 0
    with h5py.File(io.BytesIO(fc.reference_files()["rmap"]), "r") as f:
        assert np.asarray(f["cells"]).size > 0


@_bug("up-vector-extreme")
@pytest.mark.parametrize("up", ["1e200 1e200 1", "1e-200 1e-200 0"])
def test_up_vector_of_extreme_magnitude_maps_onto_z(up: str) -> None:
    from baseplace.terrain.io import load_transform

    u = np.array([float(v) for v in up.split()])
    u /= np.abs(u).max()
    np.testing.assert_allclose(load_transform(up)[:3, :3] @ (u / np.linalg.norm(u)), [0, 0, 1], atol=1e-9)


def test_loaded_values_keep_their_invariants(tmp_path: Path) -> None:
    """Found as 'loaded' notes (valid checksums, inconsistent contents), not crashes."""
    from baseplace.placement.surface_map import parse_polygon
    from baseplace.placement.surface_storage import load_surface_map
    from baseplace.reachability.storage import load_map

    with pytest.raises(BaseplaceError, match="within 1e"):  # its area overflowed to inf
        parse_polygon([[0.07, 0.89], [3.5e38, 6.55e4], [-0.8, 1e308]])
    doc = json.loads(_json_attr("smap", "meta"))
    for change in ({"polygon": None}, {"origin": [1e-300, 1e-300, 0.0]}, {"resolution": 0.0}):
        with pytest.raises(BaseplaceError, match="truncated or corrupt"):
            load_surface_map(_rewrite("smap", tmp_path, meta=json.dumps(doc | change)))
    for grid in ({"origin": [1e20, math.nan]}, {"voxel_size": math.inf}, {"voxel_size": 0}):
        with pytest.raises(BaseplaceError, match="truncated or corrupt"):
            load_map(_rewrite("rmap", tmp_path, grid=_json_attr("rmap", "grid", **grid)))
    manip = fc.reference_contents("rmap")[2]["manipulability"]
    with pytest.raises(BaseplaceError, match="truncated or corrupt"):
        load_map(_rewrite("rmap", tmp_path, arrays={"manipulability": manip[:-1]}))
