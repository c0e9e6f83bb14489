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
