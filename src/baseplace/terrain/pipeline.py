"""Points to planar regions in one call: voxels, height map, segmentation, region graph."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, unknown
from baseplace.terrain.graph import GraphSettings, build_region_graph
from baseplace.terrain.heightmap import HeightMap, check_cells
from baseplace.terrain.segmentation import (
    BaselineSegmenter,
    NoSupportError,
    RobustSegmenter,
    Segmentation,
    Segmenter,
)
from baseplace.terrain.voxels import VoxelMap, voxelization_bytes

if TYPE_CHECKING:
    import networkx as nx

ALGORITHMS = ("robust", "baseline")


def make_segmenter(algorithm: str) -> Segmenter:
    """The segmenter called ``algorithm`` ("robust" or "baseline") with default settings."""
    if algorithm == "robust":
        return RobustSegmenter()
    if algorithm == "baseline":
        return BaselineSegmenter()
    raise unknown("segmentation algorithm", algorithm, ALGORITHMS)


@dataclass(frozen=True)
class Terrain:
    """Everything the perception layer derives from a cloud.

    Attributes:
        voxels: occupied voxels (seed 000: 25 mm).
        segmentation: height map, labels and planar regions.
        polygons: each region's outline (a shapely Polygon or MultiPolygon) by region id, the
            ``polygon`` of its node in :attr:`graph`.
        timings_ms: voxels, height map, segmentation steps, graph [ms].
        make_graph: returns the region graph; called on the first read of :attr:`graph`.
    """

    voxels: VoxelMap
    segmentation: Segmentation
    polygons: dict[int, Any]
    timings_ms: dict[str, float]
    make_graph: Callable[[], nx.MultiGraph] = field(repr=False, compare=False)

    @classmethod
    def with_graph(
        cls, voxels: VoxelMap, segmentation: Segmentation, graph: nx.MultiGraph, timings_ms: dict[str, float]
    ) -> Terrain:
        """The terrain of a region graph already built (its nodes' ``polygon``s are the outlines)."""
        polygons = {r.id: graph.nodes[r.id]["polygon"] for r in segmentation.regions}
        return cls(voxels, segmentation, polygons, timings_ms, lambda: graph)

    @cached_property
    def graph(self) -> nx.MultiGraph:
        """The region graph (networkx MultiGraph), made on first use.

        A terrain read back from the cache (:mod:`baseplace.terrain.cache`) builds it only here, so
        a placement, which reads only :attr:`polygons`, never imports networkx (0.05-0.13 s).
        """
        return self.make_graph()


def terrain_from_points(
    points: ArrayLike,
    algorithm: Literal["robust", "baseline"] | str = "robust",
    resolution: float | None = None,
    voxel_size: float = 0.025,
    graph_settings: GraphSettings | None = None,
) -> Terrain:
    """Segment a z-up world cloud (N, 3) [m] into planar regions and their graph.

    Args:
        points: (N, 3) z-up world cloud [m].
        algorithm: "robust" (seed 000 IV) or "baseline".
        resolution: height-map cell [m]; None: chosen from the cloud's extent and point spacing
            (:func:`~baseplace.terrain.diagnose.auto_resolution`: 5 cm for a room, 2 cm for a table
            in a camera's view).
        voxel_size: voxel edge [m] (seed 000: 25 mm), at most the cell.
        graph_settings: region-graph settings.

    Raises:
        InputError: a bad setting, a cloud whose height map would not fit the memory cap (its cell
            count and the limit), or no level region, with its cause (too small for the cell:
            the resolution to try; no level plane: the dominant plane's normal as up vector).
    """
    # imported here: a segmentation read from the cache (terrain/cache.py) never needs the diagnosis
    from baseplace.terrain.diagnose import auto_resolution, explain_no_support

    segmenter = make_segmenter(algorithm)
    t_auto = time.perf_counter()
    if resolution is None:
        resolution = auto_resolution(points)
    t0 = time.perf_counter()
    if not (0.01 <= resolution <= 1.0):
        raise InputError(f"--resolution must be between 0.01 and 1 m, got {resolution}")
    _check_grid(points, resolution)
    voxels = VoxelMap.from_points(points, min(voxel_size, resolution))
    t1 = time.perf_counter()
    hmap = HeightMap.from_voxels(voxels, resolution)
    t2 = time.perf_counter()
    try:
        seg = refine_region_planes(segmenter.segment(hmap), voxels)
    except NoSupportError:
        raise InputError(explain_no_support(points, resolution)) from None
    t3 = time.perf_counter()
    graph = build_region_graph(seg, graph_settings)
    t4 = time.perf_counter()
    timings = {
        "voxels": (t1 - t0) * 1e3,
        "height_map": (t2 - t1) * 1e3,
        "segmentation": (t3 - t2) * 1e3,
        "graph": (t4 - t3) * 1e3,
        "total": (t4 - t0) * 1e3,
    }
    if t0 - t_auto > 1e-4:
        timings["auto_resolution"] = (t0 - t_auto) * 1e3  # not in the total, as before it was chosen
    return Terrain.with_graph(voxels, seg, graph, timings)


def _check_grid(points: ArrayLike, resolution: float) -> None:
    """Refuse a cloud whose voxelization and height map would not fit the memory cap, before either."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    reserved = voxelization_bytes(len(pts))
    xy = pts[:, :2]
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(xy).all(axis=1))
    if not finite.any():
        return  # VoxelMap.from_points says so
    lo = np.floor(np.min(xy, axis=0, where=finite[:, None], initial=np.inf) / resolution)
    hi = np.floor(np.max(xy, axis=0, where=finite[:, None], initial=-np.inf) / resolution)
    n_cols, n_rows = (hi - lo + 1).tolist()
    check_cells(n_cols, n_rows, resolution, reserved)


def terrain_json(terrain: Terrain) -> dict[str, Any]:
    """The JSON summary ``baseplace segment --json`` prints."""
    seg = terrain.segmentation
    regions = []
    for r in seg.regions:
        poly = terrain.polygons[r.id]
        polys = list(poly.geoms) if poly.geom_type == "MultiPolygon" else [poly]
        regions.append({
            "id": r.id,
            "normal": [round(float(v), 6) for v in r.normal],
            "d": round(r.d, 6),
            "tilt_deg": round(float(np.degrees(r.tilt)), 3),
            "area_m2": round(r.area, 4),
            "cells": r.n_cells,
            "centroid": [round(float(v), 4) for v in r.centroid],
            "polygon": [
                {"exterior": np.round(np.asarray(p.exterior.coords), 4).tolist(),
                 "holes": [np.round(np.asarray(h.coords), 4).tolist() for h in p.interiors]}
                for p in polys if not p.is_empty
            ],
        })  # fmt: skip
    edges = [
        {"a": int(a), "b": int(b), "p_s": np.round(e["p_s"], 4).tolist(), "p_e": np.round(e["p_e"], 4).tolist(),
         "step": round(e["step"], 4), "traversable": bool(e["traversable"])}
        for a, b, e in terrain.graph.edges(data=True)
    ]  # fmt: skip
    hmap = seg.hmap
    return {
        "height_map": {
            "origin": list(hmap.origin),
            "resolution": hmap.resolution,
            "shape": list(hmap.shape),
            "known_cells": int(hmap.known.sum()),
        },
        "voxels": len(terrain.voxels),
        "regions": regions,
        "edges": edges,
        "non_planar_cells": int(((seg.labels < 0) & hmap.known).sum()),
        "timings_ms": {
            k: round(v, 2)
            for k, v in {
                **terrain.timings_ms,
                **{f"segmentation.{k}": v for k, v in seg.timings_ms.items()},
            }.items()
        },
    }


def refine_region_planes(seg: Segmentation, voxels: VoxelMap, band: float = 0.1) -> Segmentation:
    """Refit every region's plane to all of its voxels near the plane, not only the highest ones.

    The height map keeps the highest voxel of each cell (seed 000 IV), which sits above the true
    surface when the cloud is noisy: about +1.7 sigma for 25 mm noise. The occupied voxels of a
    noisy surface spread symmetrically about it, so a least-squares plane through every voxel
    centre of the region's cells within ``band`` [m] of its plane removes that bias; on a clean
    cloud (one voxel layer) it changes nothing. Normals keep pointing up.
    """
    centres = voxels.centres
    region = seg.region_at(centres[:, :2])
    refined = []
    for r in seg.regions:
        pts = centres[region == r.id]
        pts = pts[np.abs(pts @ r.normal + r.d) <= band]
        if len(pts) < 3:
            refined.append(r)
            continue
        centroid = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - centroid, full_matrices=False)
        normal = vt[-1] if vt[-1][2] > 0 else -vt[-1]
        refined.append(dataclasses.replace(r, normal=normal, d=float(-normal @ centroid), centroid=centroid))
    return dataclasses.replace(seg, regions=refined)
