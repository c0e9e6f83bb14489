"""The region graph of seed 000 section V.

A multigraph whose vertices are planar regions (with their polygons) and whose edges join
regions that come within ``gap`` of each other. Each edge carries the line approximating the
common border, from ``p_s`` to ``p_e`` (world x, y), and whether it can be traversed: the two
planes must meet near the border, i.e. the height step between them along the border stays below
the robot's limit.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import MultiPolygon, Polygon

from baseplace.terrain.heightmap import HeightMap
from baseplace.terrain.polygons import mask_polygon
from baseplace.terrain.segmentation import PlanarRegion, Segmentation

if TYPE_CHECKING:
    import networkx as nx


@dataclass(frozen=True)
class GraphSettings:
    """How regions are joined.

    Attributes:
        gap: regions whose cells come this close are neighbours [m].
        max_step: largest height step the robot can drive over [m].
        min_border_cells: shorter common borders are ignored.
    """

    gap: float = 0.1
    max_step: float = 0.04
    min_border_cells: int = 3


def build_region_graph(seg: Segmentation, settings: GraphSettings | None = None) -> nx.MultiGraph:
    """The region graph of a segmentation.

    Vertices are region ids with attributes ``region`` (:class:`PlanarRegion`) and ``polygon``.
    Edges come from the straight sides of the lower-id region's polygon: the stretches of a side
    that lie within ``gap`` of the other region, split where the height step between the two planes
    crosses ``max_step``, so a ramp's low edge (traversable) and its high end (a drop) become
    separate edges. Edge attributes: ``p_s``, ``p_e`` (world x, y [m]), ``step`` (largest height
    difference of the two planes along the stretch [m]) and ``traversable``.
    """
    import networkx as nx
    from scipy import ndimage  # here: a cached terrain never imports it (0.5 s)

    s = settings or GraphSettings()
    hmap = seg.hmap
    graph = nx.MultiGraph()
    labels = seg.labels
    polygons = {}
    for region in seg.regions:
        polygons[region.id] = mask_polygon(labels == region.id, hmap)
        graph.add_node(region.id, region=region, polygon=polygons[region.id])
    gap_cells = s.gap / hmap.resolution
    for b in seg.regions:
        dist_to_b = ndimage.distance_transform_edt(labels != b.id)  # in cells
        for a in seg.regions:
            if a.id >= b.id:
                continue
            for p_s, p_e, step in _border_runs(polygons[a.id], a, b, dist_to_b, hmap, gap_cells, s):
                graph.add_edge(a.id, b.id, p_s=p_s, p_e=p_e, step=step, traversable=step <= s.max_step)
    return graph


def _rings(poly: Polygon | MultiPolygon) -> list[NDArray[np.float64]]:
    polys = list(poly.geoms) if isinstance(poly, MultiPolygon) else [poly]
    out = []
    for p in polys:
        if p.is_empty:
            continue
        out.append(np.asarray(p.exterior.coords))
        out.extend(np.asarray(r.coords) for r in p.interiors)
    return out


def _border_runs(
    poly: Polygon | MultiPolygon,
    a: PlanarRegion,
    b: PlanarRegion,
    dist_to_b: NDArray[np.float64],
    hmap: HeightMap,
    gap_cells: float,
    s: GraphSettings,
) -> list[tuple[NDArray[np.float64], NDArray[np.float64], float]]:
    """Straight stretches of ``a``'s polygon sides near ``b``, each with one traversability."""
    runs = []
    spacing = hmap.resolution / 2
    min_length = s.min_border_cells * hmap.resolution
    for ring in _rings(poly):
        for p0, p1 in itertools.pairwise(ring):
            length = float(np.linalg.norm(p1 - p0))
            if length < 1e-9:
                continue
            t = np.linspace(0.0, 1.0, max(2, int(np.ceil(length / spacing)) + 1))
            pts = p0 + t[:, None] * (p1 - p0)
            row, col, inside = hmap.cell_of(pts)
            near = np.zeros(len(pts), dtype=bool)
            near[inside] = dist_to_b[row[inside], col[inside]] <= gap_cells
            step = np.abs(a.height_at(pts) - b.height_at(pts))
            kind = np.where(near, np.where(step <= s.max_step, 1, 2), 0)
            start = 0
            for k in range(1, len(pts) + 1):
                if k < len(pts) and kind[k] == kind[start]:
                    continue
                if kind[start] != 0 and float(np.linalg.norm(pts[k - 1] - pts[start])) >= min_length:
                    runs.append((pts[start].copy(), pts[k - 1].copy(), float(step[start:k].max())))
                start = k
    return runs
