"""The per-user map cache stores its maps uncompressed after their first load (quicker to open)."""

from __future__ import annotations

import h5py
import numpy as np

from baseplace.files import private_dir
from baseplace.reachability import cache as map_cache
from baseplace.reachability.build import BuildSettings
from baseplace.reachability.cache import cached_map, cached_map_path
from baseplace.reachability.storage import load_map, save_map


def _gzip(path) -> bool:
    with h5py.File(path, "r") as f:
        return f["cells"].compression == "gzip" and f["counts"].compression == "gzip"


def test_a_cached_map_is_stored_plain_after_its_first_load(tiago, tiago_map, tmp_path, monkeypatch):
    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    settings = BuildSettings(samples=2_000_000, seed=3)
    path = cached_map_path(tiago, settings)
    private_dir(path.parent)
    save_map(tiago_map, path)  # as build_map leaves it: gzip
    assert _gzip(path)
    packed_size = path.stat().st_size
    for _ in range(2):
        rmap, where, built = cached_map(tiago, settings)
        assert where == path and not built
        assert np.array_equal(rmap.cells, tiago_map.cells) and np.array_equal(rmap.counts, tiago_map.counts)
        assert rmap.info == tiago_map.info and rmap.grid == tiago_map.grid
        with h5py.File(path, "r") as f:
            assert f["cells"].compression is None and f["counts"].compression is None
    assert path.stat().st_size > 5 * packed_size
    again = load_map(path, tiago)  # with all of load_map's checks (digest, robot, arm)
    assert np.array_equal(again.cells, tiago_map.cells)


def test_a_cache_that_cannot_be_rewritten_still_gives_the_map(tiago, tiago_map, tmp_path, monkeypatch):
    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    settings = BuildSettings(samples=2_000_000, seed=3)
    path = cached_map_path(tiago, settings)
    private_dir(path.parent)
    save_map(tiago_map, path)

    def refuse(*args, **kwargs):
        raise PermissionError("read-only")

    monkeypatch.setattr(map_cache, "save_map", refuse)
    rmap, _, built = cached_map(tiago, settings)
    assert not built and np.array_equal(rmap.cells, tiago_map.cells) and _gzip(path)


def test_the_default_map_is_resolved_with_the_given_settings(planar3, tmp_path, monkeypatch):
    """resolve_map builds the cached default with the caller's settings (the demo's and surface-map's --samples)."""
    from baseplace.reachability.cache import resolve_map

    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    settings = BuildSettings(samples=200_000, voxel_size=0.1)
    steps = []
    first = resolve_map(planar3, None, None, lambda step, done, total: steps.append((step, total)), settings)
    assert first.built and first.cached_at == cached_map_path(planar3, settings) and first.cached_at.is_file()
    assert first.rmap.info.samples == 200_000 and steps and {total for _, total in steps} == {200_000}
    again = resolve_map(planar3, "default", None, None, settings)
    assert not again.built and again.cached_at == first.cached_at
    assert np.array_equal(again.rmap.cells, first.rmap.cells)


def test_jobs_and_the_service_find_their_maps_through_resolve_map():
    """One map resolution: nothing but the cache itself calls cached_map, and the baseplace.demo shim is gone."""
    import ast
    from pathlib import Path

    src = Path(map_cache.__file__).parents[1]
    callers = []
    for path in sorted(src.rglob("*.py")):
        if path == Path(map_cache.__file__):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (
                node.module == "baseplace.demo" or any(a.name == "cached_map" for a in node.names)
            ):
                callers.append(f"{path.relative_to(src)}:{node.lineno}")
    assert not callers and not (src / "demo.py").exists(), callers
