"""A per-user cache of segmented terrains, so a command run twice on one cloud segments it once.

:func:`~baseplace.terrain.pipeline.terrain_from_points` is deterministic: the same points with
the same settings and the same code give the same voxels, regions and region graph. Segmenting a
660 k point room takes about a second (and importing scipy.ndimage half a second more); reading
its result back takes a few tens of milliseconds. An entry is keyed by a SHA-256 of the points'
bytes, the settings and the source of every module the segmentation runs (``terrain/*.py`` and
``arrays.py``) and the versions of numpy, scipy, numba, OpenCV, shapely and networkx, so an
edit of that code, an upgrade, a changed setting or one moved point misses the cache.

Entries are HDF5 files of plain arrays (no pickle, no variable-length strings, see
:mod:`baseplace.h5files`) under ``$BASEPLACE_CACHE/terrain`` (default ``~/.cache/baseplace``),
each with a SHA-256 of its contents. A missing, damaged, foreign or stale entry is recomputed and
rewritten; writing one that fails (a read-only cache) only costs the next run the segmentation.
The newest :data:`MAX_ENTRIES` entries are kept.
"""

from __future__ import annotations

import hashlib
import json
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from baseplace.terrain.graph import GraphSettings
    from baseplace.terrain.pipeline import Terrain

FORMAT = "baseplace-terrain"
FORMAT_VERSION = 1
MAX_ENTRIES = 16
"""Entries kept; the oldest (by modification time) go when a new one is written."""


@cache
def code_digest() -> str:
    """SHA-256 of the segmenting code: ``terrain/*.py``, ``arrays.py`` and the libraries' versions."""
    from importlib.metadata import version

    import cv2
    import numba
    import scipy
    import shapely

    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for lib in (np, scipy, numba, cv2, shapely):
        h.update(f"{lib.__name__} {lib.__version__}\0".encode())
    h.update(f"networkx {version('networkx')}\0".encode())  # not imported: a cached terrain needs no graph
    for path in [*sorted(here.glob("*.py")), here.parent / "arrays.py"]:
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def terrain_key(
    points: np.ndarray,
    algorithm: str,
    resolution: float | None,
    voxel_size: float,
    graph_settings: GraphSettings | None,
) -> str:
    """The cache key (hex SHA-256) of segmenting ``points`` (float64, C order) with these settings."""
    h = hashlib.sha256()
    settings = f"{FORMAT}/{FORMAT_VERSION} {code_digest()} {algorithm} {resolution!r} {voxel_size!r} {graph_settings!r}"
    h.update(settings.encode() + b"\0" + repr(points.shape).encode() + b"\0")
    h.update(_raw(points))
    return h.hexdigest()


def _raw(a: np.ndarray) -> memoryview | bytes:
    """The bytes of a C-contiguous array, without a copy."""
    return a.data.cast("B") if a.size else b""


def check_up_direction_cached(points: ArrayLike, optical: bool = False) -> None:
    """:func:`~baseplace.terrain.diagnose.check_up_direction`, skipped for a cloud that passed it before.

    A pass is remembered as a small file holding the key (the points' bytes, ``optical``, the
    code); a cloud that fails is checked, and refused, every time.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    key = terrain_key(pts, "up-direction", None, 0.0, None) + f"-optical{int(bool(optical))}"
    marker = terrain_dir() / f"up-{hashlib.sha256(key.encode()).hexdigest()[:32]}.ok"
    try:
        if marker.read_text(encoding="ascii") == key:
            return
    except (OSError, UnicodeError):
        pass
    from baseplace.terrain.diagnose import check_up_direction

    check_up_direction(pts, optical=optical)  # raises for a cloud that does not look z-up
    from baseplace.errors import InputError
    from baseplace.files import atomic_write, private_dir

    try:
        private_dir(marker.parent)
        with atomic_write(marker, "up-direction mark") as tmp:
            tmp.write_text(key, encoding="ascii")
        _prune(marker.parent, "up-*.ok", 4 * MAX_ENTRIES)
    except (OSError, InputError):
        pass


def _prune(directory: Path, pattern: str, keep: int) -> None:
    """Delete all but the ``keep`` newest files matching ``pattern``."""
    entries = sorted(directory.glob(pattern), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in entries[keep:]:
        old.unlink(missing_ok=True)


def terrain_dir() -> Path:
    """Where the cache keeps segmented terrains (beside the kernels and the maps)."""
    from baseplace.files import cache_root

    return cache_root() / "terrain"


def cached_terrain(
    points: ArrayLike,
    algorithm: str = "robust",
    resolution: float | None = None,
    voxel_size: float = 0.025,
    graph_settings: GraphSettings | None = None,
) -> Terrain:
    """:func:`~baseplace.terrain.pipeline.terrain_from_points` of ``points``, read from the cache if there.

    Same arguments, result and errors as ``terrain_from_points``; a computed terrain is stored.
    Its ``timings_ms`` are those of the run that computed it, plus ``cache_read`` [ms] when read.
    """
    import time

    pts = np.ascontiguousarray(points, dtype=np.float64)
    t0 = time.perf_counter()
    key = terrain_key(pts, algorithm, resolution, voxel_size, graph_settings)
    path = terrain_dir() / f"terrain-{key[:32]}.h5"
    terrain = read_terrain(path, key)
    if terrain is not None:
        terrain.timings_ms["cache_read"] = (time.perf_counter() - t0) * 1e3
        return terrain
    from baseplace.terrain.pipeline import terrain_from_points

    terrain = terrain_from_points(pts, algorithm, resolution, voxel_size, graph_settings)
    from baseplace.errors import InputError
    from baseplace.files import OutputError, is_disk_full, skip_cache_entry

    # a cache that cannot be written (full, read-only, another user's) costs the next run the segmentation
    try:
        write_terrain(path, key, terrain)
    except (OutputError, OSError) as exc:
        if isinstance(exc, OutputError) or is_disk_full(exc):
            skip_cache_entry("the segmentation", path.parent, exc)
    except InputError:
        pass
    return terrain


def _arrays(terrain: Terrain) -> dict[str, np.ndarray]:
    """The terrain as named arrays (polygons as WKB, concatenated)."""
    import shapely

    seg = terrain.segmentation
    regions = seg.regions
    wkb = [shapely.to_wkb(terrain.polygons[r.id]) for r in regions]
    edges = list(terrain.graph.edges(keys=True, data=True))
    return {
        "voxel_keys": terrain.voxels.keys,
        "voxel_resolution": np.array([terrain.voxels.resolution]),
        "hmap_origin": np.array(seg.hmap.origin, dtype=np.float64),
        "hmap_resolution": np.array([seg.hmap.resolution]),
        "hmap_raw": seg.hmap.raw,
        "hmap_smooth": seg.hmap.smooth,
        "labels": seg.labels,
        "region_ids": np.array([r.id for r in regions], dtype=np.int64),
        "region_normals": np.array([r.normal for r in regions], dtype=np.float64).reshape(-1, 3),
        "region_d": np.array([r.d for r in regions], dtype=np.float64),
        "region_centroids": np.array([r.centroid for r in regions], dtype=np.float64).reshape(-1, 3),
        "region_cells": np.array([r.n_cells for r in regions], dtype=np.int64),
        "region_area": np.array([r.area for r in regions], dtype=np.float64),
        "polygon_wkb": np.frombuffer(b"".join(wkb), dtype=np.uint8),
        "polygon_ends": np.cumsum([len(w) for w in wkb], dtype=np.int64),
        "edge_ends": np.array([(a, b, k) for a, b, k, _ in edges], dtype=np.int64).reshape(-1, 3),
        "edge_p_s": np.array([e["p_s"] for *_, e in edges], dtype=np.float64).reshape(-1, 2),
        "edge_p_e": np.array([e["p_e"] for *_, e in edges], dtype=np.float64).reshape(-1, 2),
        "edge_step": np.array([e["step"] for *_, e in edges], dtype=np.float64),
        "edge_traversable": np.array([e["traversable"] for *_, e in edges], dtype=np.uint8),
        "timings": np.frombuffer(
            json.dumps({"terrain": terrain.timings_ms, "segmentation": seg.timings_ms}).encode(),
            dtype=np.uint8,
        ),
    }


def _digest(key: str, arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256(key.encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\0{name} {a.dtype.str} {a.shape}\0".encode())
        h.update(_raw(a))
    return h.hexdigest()


def write_terrain(path: Path, key: str, terrain: Terrain) -> None:
    """Store ``terrain`` under ``key`` at ``path`` (atomically), then drop the oldest entries."""
    from baseplace.files import atomic_hdf5, private_dir
    from baseplace.h5files import short_text, write_header

    private_dir(path.parent)
    arrays = _arrays(terrain)
    with atomic_hdf5(path, "terrain cache entry") as f:
        write_header(f, FORMAT, FORMAT_VERSION)
        f.attrs["key"] = short_text(key)
        f.attrs["sha256"] = short_text(_digest(key, arrays))
        for name, a in arrays.items():
            f.create_dataset(
                name,
                data=a,
                **(
                    {"compression": "gzip", "compression_opts": 1, "shuffle": True}
                    if a.nbytes > 65536
                    else {}
                ),
            )
    _prune(path.parent, "terrain-*.h5", MAX_ENTRIES)


def read_terrain(path: Path, key: str) -> Terrain | None:
    """The terrain stored under ``key`` at ``path``; None if absent, damaged, stale or inconsistent."""
    if not path.is_file():
        return None
    try:
        return _read(path, key)
    except Exception:  # any damage (h5py, numpy, shapely, json errors): recompute
        return None


def _read(path: Path, key: str) -> Terrain | None:
    import h5py

    from baseplace.h5files import attr_text, read_array

    with h5py.File(path, "r") as f:
        if attr_text(f.attrs, "format") != FORMAT or int(f.attrs["format_version"]) != FORMAT_VERSION:
            return None
        if attr_text(f.attrs, "key") != key:
            return None
        arrays = {name: read_array(f, name, path) for name in f}
        if attr_text(f.attrs, "sha256") != _digest(key, arrays):
            return None
    return _terrain(arrays)


def _terrain(a: dict[str, Any]) -> Terrain | None:
    """The terrain of :func:`_arrays`' arrays; None if they do not fit together."""
    import shapely

    from baseplace.terrain.heightmap import HeightMap
    from baseplace.terrain.pipeline import Terrain
    from baseplace.terrain.segmentation import PlanarRegion, Segmentation
    from baseplace.terrain.voxels import VoxelMap

    n = len(a["region_ids"])
    if not (
        a["voxel_keys"].ndim == 2
        and a["voxel_keys"].shape[1] == 3
        and a["hmap_raw"].ndim == 2
        and a["hmap_raw"].shape == a["hmap_smooth"].shape == a["labels"].shape
        and np.array_equal(a["region_ids"], np.arange(n))
        and all(
            len(a[k]) == n
            for k in (
                "region_normals",
                "region_d",
                "region_centroids",
                "region_cells",
                "region_area",
                "polygon_ends",
            )
        )
        and (n == 0 or int(a["polygon_ends"][-1]) == len(a["polygon_wkb"]))
        and all(
            len(a[k]) == len(a["edge_ends"])
            for k in ("edge_p_s", "edge_p_e", "edge_step", "edge_traversable")
        )
    ):
        return None
    hmap = HeightMap(
        (float(a["hmap_origin"][0]), float(a["hmap_origin"][1])),
        float(a["hmap_resolution"][0]),
        a["hmap_raw"],
        a["hmap_smooth"],
    )
    regions = [
        PlanarRegion(
            k,
            a["region_normals"][k],
            float(a["region_d"][k]),
            a["region_centroids"][k],
            int(a["region_cells"][k]),
            float(a["region_area"][k]),
        )
        for k in range(n)
    ]
    timings = json.loads(bytes(a["timings"]).decode())
    seg = Segmentation(hmap, a["labels"], regions, timings["segmentation"])
    starts = [0, *a["polygon_ends"][:-1].tolist()]
    wkb = bytes(a["polygon_wkb"])
    polygons = {r.id: shapely.from_wkb(wkb[s:e]) for r, s, e in zip(regions, starts, a["polygon_ends"].tolist(), strict=True)}  # fmt: skip
    ends = a["edge_ends"]
    if ends.ndim != 2 or ends.shape[1] != 3 or not np.all((ends[:, :2] >= 0) & (ends[:, :2] < n)):
        return None
    edges = list(zip(ends.tolist(), a["edge_p_s"], a["edge_p_e"], a["edge_step"].tolist(),
                     a["edge_traversable"].tolist(), strict=True))  # fmt: skip

    def make_graph() -> Any:
        """The region graph, as :func:`~baseplace.terrain.graph.build_region_graph` made it."""
        import networkx as nx

        graph = nx.MultiGraph()
        for r in regions:
            graph.add_node(r.id, region=r, polygon=polygons[r.id])
        for (i, j, k), p_s, p_e, step, trav in edges:
            graph.add_edge(i, j, key=k, p_s=p_s, p_e=p_e, step=float(step), traversable=bool(trav))
        return graph

    voxels = VoxelMap(float(a["voxel_resolution"][0]), a["voxel_keys"])
    return Terrain(voxels, seg, polygons, timings["terrain"], make_graph)
