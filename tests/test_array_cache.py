"""The on-disk cache of derived arrays: one computation across processes, hostile files ignored."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.world import array_cache
from baseplace.world.array_cache import cached_array


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path))
    return tmp_path / "fields"


def _counted(value):
    calls = []

    def compute():
        calls.append(1)
        return value.copy()

    return compute, calls


def test_an_array_is_computed_once_and_read_back_equal(cache):
    value = np.random.default_rng(0).random((7, 5, 3)).astype(np.float32)
    compute, calls = _counted(value)
    inputs = (np.arange(4), 0.01, "x")
    first = cached_array("field", inputs, (7, 5, 3), np.float32, compute)
    second = cached_array("field", inputs, (7, 5, 3), np.float32, compute)
    assert len(calls) == 1
    np.testing.assert_array_equal(first, value)
    np.testing.assert_array_equal(second, value)
    assert second.dtype == np.float32 and second.shape == (7, 5, 3)
    cached_array(
        "field", (np.arange(4), 0.02, "x"), (7, 5, 3), np.float32, compute
    )  # other inputs: other key
    assert len(calls) == 2
    assert len(list(cache.glob("field-*.npy"))) == 2 and not list(cache.glob("*.tmp"))


@pytest.mark.parametrize(
    "write",
    [
        lambda f: f.write_bytes(b""),  # empty
        lambda f: f.write_bytes(f.read_bytes()[:-8]),  # truncated
        lambda f: f.write_bytes(f.read_bytes()[:10] + b"x" * 50 + f.read_bytes()[60:]),  # a garbled header
        lambda f: np.save(f, np.zeros((7, 5, 3), dtype=np.float64)),  # another dtype
        lambda f: np.save(f, np.zeros((5, 7, 3), dtype=np.float32)),  # another shape, same size
        lambda f: np.save(f, np.array([{"a": 1}] * 105, dtype=object), allow_pickle=True),  # a pickle
    ],
)
def test_a_file_that_is_not_exactly_the_array_is_ignored_and_computed_again(cache, write):
    value = np.arange(105, dtype=np.float32).reshape(7, 5, 3)
    compute, calls = _counted(value)
    cached_array("field", (1,), (7, 5, 3), np.float32, compute)
    (path,) = cache.glob("field-*.npy")
    write(path)
    out = cached_array("field", (1,), (7, 5, 3), np.float32, compute)
    assert len(calls) == 2
    np.testing.assert_array_equal(out, value)


def test_a_header_declaring_a_huge_array_allocates_nothing(cache, monkeypatch):
    """A file whose header declares 1e12 values over a few bytes is refused before NumPy reads it."""
    value = np.zeros((7, 5, 3), dtype=np.float32)
    compute, _ = _counted(value)
    cached_array("field", (2,), (7, 5, 3), np.float32, compute)
    (path,) = cache.glob("field-*.npy")
    with path.open("wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (10**12,)})
        f.write(b"\0" * 420)
    read = []
    monkeypatch.setattr(array_cache.np, "fromfile", lambda *a, **k: read.append(1))
    assert array_cache._read(path, (7, 5, 3), np.dtype("<f4")) is None
    assert not read


def test_an_unwritable_cache_costs_a_warning_not_the_result(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("BASEPLACE_CACHE", str(blocker))  # a file where the cache folder should be
    value = np.ones((2, 2), dtype=np.float32)
    with pytest.warns(Warning, match="not cached"):
        out = cached_array("field", (3,), (2, 2), np.float32, lambda: value)
    np.testing.assert_array_equal(out, value)


def test_an_edit_of_the_computing_code_computes_the_array_again(cache, monkeypatch):
    """The key holds the source file of the function that computes the array (here this test file's)."""
    value = np.ones((3,), dtype=np.float32)
    compute, calls = _counted(value)
    cached_array("field", (4,), (3,), np.float32, compute)
    assert array_cache._source(compute) == open(__file__, "rb").read()
    monkeypatch.setattr(array_cache, "_source", lambda f: b"an edited version of the code")
    cached_array("field", (4,), (3,), np.float32, compute)
    assert len(calls) == 2


def test_a_state_filter_reads_its_robot_arrays_back_as_computed(cache, monkeypatch):
    """The sphere covers, self distance tables and anchor fields: computed once, then read, never computed again."""
    from baseplace.robots.model import Robot
    from baseplace.world.environment import Environment
    from baseplace.world.state_filter import sphere_cover

    first_robot = Robot("tiago")  # a new robot: no array of it kept in this process
    first = Environment(first_robot, {}).state_filter(first_robot.arm())
    names = sorted(path.name.split("-")[0] for path in cache.glob("*.npy"))
    n_tables = int((first._tables[0] >= 0).sum())
    assert n_tables >= 3 and names.count("self_table") == n_tables
    assert names.count("sphere_covers") == 1 and names.count("anchor_field") >= 1

    def computed_again(path, value):
        raise AssertionError(f"{path.name} was computed again")

    monkeypatch.setattr(array_cache, "_write", computed_again)
    second_robot = Robot("tiago")
    second = Environment(second_robot, {}).state_filter(second_robot.arm())
    for mine, read in [
        (first._cover, second._cover),
        (first._tables, second._tables),
        (first._anchors, second._anchors),
    ]:
        for a, b in zip(mine, read, strict=True):
            np.testing.assert_array_equal(a, b)
    # the covers read back are sphere_cover's, geometry by geometry
    starts, _, _, radii = second._cover
    geometries = Environment(second_robot, {}, self_collision=False).geom.geometryObjects
    for k in range(len(starts) - 1):
        np.testing.assert_array_equal(
            radii[starts[k] : starts[k + 1]], sphere_cover(geometries[k].geometry)[1]
        )
