"""The segmentation cache (terrain.cache): what it returns equals a fresh segmentation, and a
damaged, foreign or stale entry is recomputed, never trusted and never a crash."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import shapely

from baseplace.errors import InputError
from baseplace.jobs.inputs import CloudInput
from baseplace.jobs.navigate import NavigateJob, navigate_job
from baseplace.jobs.place import PlaceJob, place_job
from baseplace.placement.pipeline import PlaceSettings
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.cache import cached_terrain, check_up_direction_cached, terrain_dir
from baseplace.terrain.io import Cloud, save_cloud
from baseplace.terrain.pipeline import Terrain, terrain_from_points


@pytest.fixture(scope="module")
def points() -> np.ndarray:
    rng = np.random.default_rng(5)
    scene = generate_scene(SceneSettings(n_planes=2, extent=(6.0, 6.0)), rng)
    return scene.sample_cloud(rng)


@pytest.fixture(scope="module")
def fresh(points) -> Terrain:
    """The oracle: segmented now, no cache involved."""
    return terrain_from_points(points)


@pytest.fixture()
def cache_root(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def assert_same_terrain(a: Terrain, b: Terrain) -> None:
    assert a.voxels.resolution == b.voxels.resolution and np.array_equal(a.voxels.keys, b.voxels.keys)
    sa, sb = a.segmentation, b.segmentation
    assert sa.hmap.origin == sb.hmap.origin and sa.hmap.resolution == sb.hmap.resolution
    assert np.array_equal(sa.hmap.raw, sb.hmap.raw, equal_nan=True)
    assert np.array_equal(sa.hmap.smooth, sb.hmap.smooth, equal_nan=True)
    assert sa.labels.dtype == sb.labels.dtype and np.array_equal(sa.labels, sb.labels)
    assert len(sa.regions) == len(sb.regions) >= 2
    for ra, rb in zip(sa.regions, sb.regions, strict=True):
        assert (ra.id, ra.d, ra.n_cells, ra.area) == (rb.id, rb.d, rb.n_cells, rb.area)
        assert np.array_equal(ra.normal, rb.normal) and np.array_equal(ra.centroid, rb.centroid)
        assert a.graph.nodes[ra.id]["region"] == ra and b.graph.nodes[rb.id]["region"] == rb
        pa, pb = a.graph.nodes[ra.id]["polygon"], b.graph.nodes[rb.id]["polygon"]
        assert pa.geom_type == pb.geom_type and shapely.equals_exact(pa, pb, tolerance=0.0)
        assert a.polygons[ra.id] is pa and b.polygons[rb.id] is pb  # the outlines a placement reads
    ea = list(a.graph.edges(keys=True, data=True))
    eb = list(b.graph.edges(keys=True, data=True))
    assert len(ea) == len(eb) >= 1
    for (i, j, k, da), (i2, j2, k2, db) in zip(ea, eb, strict=True):
        assert (i, j, k) == (i2, j2, k2) and set(da) == set(db)
        assert np.array_equal(da["p_s"], db["p_s"]) and np.array_equal(da["p_e"], db["p_e"])
        assert da["step"] == db["step"] and da["traversable"] is db["traversable"]


def test_a_cached_terrain_equals_a_fresh_segmentation(points, fresh, cache_root):
    first = cached_terrain(points)  # computed and stored
    assert "cache_read" not in first.timings_ms
    entries = list(terrain_dir().glob("terrain-*.h5"))
    assert len(entries) == 1 and entries[0].is_relative_to(cache_root)
    second = cached_terrain(points)  # read back
    assert "cache_read" in second.timings_ms
    assert_same_terrain(second, fresh)
    assert_same_terrain(first, fresh)


def test_a_cached_terrain_imports_networkx_only_for_its_graph(points, cache_root):
    """A placement reads the polygons only: a new process reading the entry never imports networkx."""
    import subprocess
    import sys

    cached_terrain(points)
    np.save(cache_root / "points.npy", points)
    code = (
        "import sys, numpy as np\n"
        "from baseplace.terrain.cache import cached_terrain\n"
        f"t = cached_terrain(np.load({str(cache_root / 'points.npy')!r}))\n"
        "assert 'cache_read' in t.timings_ms and len(t.polygons) >= 2\n"
        "assert 'networkx' not in sys.modules, 'read'\n"
        "assert t.graph.number_of_edges() >= 1 and 'networkx' in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_a_terrain_of_one_region_without_edges_round_trips(cache_root):
    rng = np.random.default_rng(3)
    flat = generate_scene(SceneSettings(n_planes=0, with_box=False, extent=(4.0, 4.0)), rng).sample_cloud(rng)
    fresh = terrain_from_points(flat)
    assert len(fresh.segmentation.regions) == 1 and fresh.graph.number_of_edges() == 0
    cached_terrain(flat)
    again = cached_terrain(flat)
    assert "cache_read" in again.timings_ms
    assert again.graph.number_of_edges() == 0 and len(again.segmentation.regions) == 1
    assert np.array_equal(again.segmentation.labels, fresh.segmentation.labels)
    assert np.array_equal(again.voxels.keys, fresh.voxels.keys)


def test_other_points_or_settings_miss_the_cache(points, fresh, cache_root):
    cached_terrain(points)
    moved = points.copy()
    moved[0, 2] += 1e-6
    assert "cache_read" not in cached_terrain(moved).timings_ms
    assert "cache_read" not in cached_terrain(points, resolution=0.1).timings_ms
    assert len(list(terrain_dir().glob("terrain-*.h5"))) == 3
    assert_same_terrain(cached_terrain(points), fresh)


def _damage_bytes(path: Path) -> None:
    data = bytearray(path.read_bytes())
    for k in range(len(data) // 3, len(data) // 3 + 64):
        data[k] ^= 0xFF
    path.write_bytes(bytes(data))


def _damage_labels(path: Path) -> None:
    with h5py.File(path, "r+") as f:  # a well-formed file whose contents no longer match its checksum
        labels = f["labels"][()]
        labels[labels == 0] = 1
        f["labels"][...] = labels


def _foreign_key(path: Path) -> None:
    with h5py.File(path, "r+") as f:
        f.attrs["key"] = np.bytes_(b"0" * 64)


@pytest.mark.parametrize(
    "damage",
    [
        _damage_bytes,
        _damage_labels,
        _foreign_key,
        lambda p: p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2]),
        lambda p: p.write_bytes(b"not an HDF5 file"),
        lambda p: p.write_bytes(b""),
    ],
    ids=["flipped-bytes", "edited-labels", "foreign-key", "truncated", "garbage", "empty"],
)
def test_a_damaged_entry_is_recomputed_and_rewritten(points, fresh, cache_root, damage):
    cached_terrain(points)
    (entry,) = terrain_dir().glob("terrain-*.h5")
    damage(entry)
    again = cached_terrain(points)
    assert "cache_read" not in again.timings_ms  # not trusted: segmented again
    assert_same_terrain(again, fresh)
    assert "cache_read" in cached_terrain(points).timings_ms  # and stored again, whole


def test_an_unwritable_cache_only_costs_the_segmentation(points, fresh, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("BASEPLACE_CACHE", str(blocker / "cache"))  # below a file: cannot be created
    assert_same_terrain(cached_terrain(points), fresh)


def test_the_up_direction_is_checked_until_a_cloud_passes(points, cache_root, monkeypatch):
    from baseplace.terrain import diagnose

    calls = []
    real = diagnose.check_up_direction
    monkeypatch.setattr(diagnose, "check_up_direction", lambda *a, **k: calls.append(1) or real(*a, **k))
    c, s = np.cos(np.pi / 2), np.sin(np.pi / 2)
    on_its_side = points @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
    for _ in range(2):  # refused every time, never remembered
        with pytest.raises(InputError, match="does not look z-up"):
            check_up_direction_cached(on_its_side)
    assert len(calls) == 2
    check_up_direction_cached(points)
    check_up_direction_cached(points)  # remembered
    assert len(calls) == 3
    check_up_direction_cached(points, optical=True)  # another check: not the same key
    assert len(calls) == 4
    for marker in terrain_dir().glob("up-*.ok"):
        marker.write_text("something else")  # a mark that does not hold its key is ignored
    check_up_direction_cached(points)
    assert len(calls) == 5


def test_place_with_the_cache_equals_place_without(points, tiago, tiago_map, cache_root, tmp_path):
    cloud = tmp_path / "scene.ply"
    save_cloud(Cloud(points, source="test"), cloud)
    rng = np.random.default_rng(5)
    plane = generate_scene(SceneSettings(n_planes=2, extent=(6.0, 6.0)), rng).planes[1]
    cx, cy = plane.center
    target = f"{cx} {cy} {float(plane.z(np.array([[cx, cy]]))[0]) + 0.75} 0 1.5708 0"
    settings = PlaceSettings(
        placements=2, tries=200, motion=None, stand_on="any"
    )  # plane 1 may be a raised platform

    def run(use_cache: bool):
        job = PlaceJob([target], robot=tiago, map=tiago_map, cloud=CloudInput(paths=[str(cloud)], transforms=[None]),
                       settings=settings, segmentation_cache=use_cache)  # fmt: skip
        return place_job(job)

    without = run(False)
    assert not list(cache_root.glob("terrain/terrain-*.h5"))
    stored, read = run(True), run(True)
    assert "segmentation_cache_read" not in stored.timings_ms and "segmentation_cache_read" in read.timings_ms
    assert without.placements and without.placements == stored.placements == read.placements
    assert without.failures == stored.failures == read.failures and without.regions == read.regions


def test_navigate_with_the_cache_equals_navigate_without(tiago, cache_root, tmp_path):
    from test_navigation import _ramp_scene

    cloud = tmp_path / "ramp.npy"
    np.save(cloud, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))

    def run(use_cache: bool, planner: str):
        job = NavigateJob("-2 0.6 0", "1.7 0.6 0", CloudInput(paths=[str(cloud)], transforms=[None]), robot=tiago,
                          planner=planner, seed=1, segmentation_cache=use_cache)  # fmt: skip
        return navigate_job(job).to_json()

    for planner in ("regions", "rrt"):
        without = run(False, planner)
        with_cache = run(True, planner)
        assert without["poses"] and without["poses"] == with_cache["poses"], planner
        assert (
            without["regions"] == with_cache["regions"] == [0, 1]
            and without["length"] == with_cache["length"]
        )
    assert (
        len(list(cache_root.glob("terrain/terrain-*.h5"))) == 1
    )  # stored by the first run, read by the second
