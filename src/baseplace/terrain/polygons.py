"""Region polygons (seed 000 III-A), the footprint-inside-region test, and polygons given by hand.

Contours come from OpenCV's ``findContours`` (Suzuki and Abe's border following, the algorithm
seed 000 cites), with holes (an object lying on a ramp is a hole in the ramp's region), and are
simplified with Douglas-Peucker. Vertices are the centres of the region's boundary cells, so a
polygon lies up to half a cell inside the region's true edge: conservative for footprints.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry import MultiPolygon, Polygon

from baseplace.errors import InputError, brief
from baseplace.geometry.poses import FloatArray
from baseplace.terrain.heightmap import HeightMap

CIRCLE_VERTICES = 32


MAX_COORDINATE = 1e6  # m: beyond any workspace; keeps areas and grid sizes finite


def parse_polygon(text: str | ArrayLike) -> FloatArray:
    """A simple polygon from ``"x1,y1;x2,y2;..."`` or an (N, 2) array; (N, 2) vertices [m].

    Raises:
        InputError: unparsable text, fewer than 3 vertices, a vertex beyond
            :data:`MAX_COORDINATE`, zero area or a self-intersection.
    """
    if isinstance(text, str):
        try:
            pts = np.array([[float(v) for v in p.split(",")] for p in text.strip().strip(";").split(";")])
        except ValueError:
            raise InputError(f'polygon must be "x1,y1;x2,y2;x3,y3;..." in metres, got {text!r}') from None
    else:
        try:
            pts = np.asarray(text, dtype=float)
        except (TypeError, ValueError):
            raise InputError("polygon must be an (N, 2) array of numbers in metres") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
        raise InputError(f"polygon needs at least 3 finite (x, y) vertices, got {brief(pts.tolist())}")
    if np.abs(pts).max() > MAX_COORDINATE:
        raise InputError(f"polygon vertices must lie within {MAX_COORDINATE:g} m of the origin")
    centred = pts - pts.mean(axis=0)
    if np.linalg.matrix_rank(centred, tol=1e-6) < 2:
        raise InputError(f"polygon is degenerate: its vertices {pts.tolist()} are collinear")
    if not shapely.LinearRing(pts).is_simple:
        raise InputError("polygon is not simple: its edges cross; list its vertices in order around it")
    area = shapely.Polygon(pts).area
    if area < 1e-6:
        raise InputError(f"polygon is degenerate: its area is {area:.2g} m^2")
    return pts


def mask_polygon(
    mask: NDArray[np.bool_], hmap: HeightMap, simplify_cells: float = 0.5
) -> Polygon | MultiPolygon:
    """Polygon (with holes) of the cells where ``mask`` (H, W) is True, in world x, y [m]."""
    img = np.ascontiguousarray(mask, dtype=np.uint8)
    contours, hierarchy = cv2.findContours(img, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return Polygon()
    res = hmap.resolution
    ox, oy = hmap.origin

    def world(contour: NDArray[np.int32] | cv2.typing.MatLike) -> NDArray[np.float64]:
        c = cv2.approxPolyDP(contour, simplify_cells, True)[:, 0, :].astype(float)
        return np.c_[ox + (c[:, 0] + 0.5) * res, oy + (c[:, 1] + 0.5) * res]

    shells = []
    for k, (_, _, child, parent) in enumerate(hierarchy[0]):
        if parent != -1:
            continue
        outer = world(contours[k])
        holes = []
        while child != -1:
            hole = world(contours[child])
            if len(hole) >= 3:
                holes.append(hole)
            child = hierarchy[0][child][0]
        if len(outer) >= 3:
            poly = Polygon(outer, holes)
            shells.append(poly if poly.is_valid else poly.buffer(0))  # simplified holes may touch
        elif len(outer) > 0:  # a one- or two-cell sliver: a thin rectangle around its cells
            shells.append(shapely.MultiPoint(outer).buffer(res / 2, cap_style="square"))
    if not shells:
        return Polygon()
    merged = shapely.union_all(shells)
    if isinstance(merged, (Polygon, MultiPolygon)):
        return merged
    parts = [g for g in shapely.get_parts(merged) if isinstance(g, Polygon) and g.area > 0]
    return MultiPolygon(parts) if parts else Polygon()


def footprint_outline(radius: float | None, polygon: ArrayLike | None) -> NDArray[np.float64]:
    """Footprint vertices (K, 2) in the base frame [m]: the polygon, or a circle as a 32-gon.

    The 32-gon circumscribes the circle, so it is never smaller than the true footprint.
    """
    if polygon is not None:
        return np.asarray(polygon, dtype=float).reshape(-1, 2)
    assert radius is not None
    k = np.arange(CIRCLE_VERTICES)
    r = radius / math.cos(math.pi / CIRCLE_VERTICES)
    return r * np.c_[np.cos(2 * np.pi * k / CIRCLE_VERTICES), np.sin(2 * np.pi * k / CIRCLE_VERTICES)]


def footprint_in_world(outline: ArrayLike, T_world_base: ArrayLike) -> Polygon:
    """The footprint (K, 2) placed at ``T_world_base`` (4, 4), projected onto the xy plane."""
    pts = np.asarray(outline, dtype=float)
    T = np.asarray(T_world_base, dtype=float)
    world = pts @ T[:2, :2].T + T[:2, 3]  # base-frame points (x, y, 0)
    return Polygon(world)


def footprint_inside(
    region: Polygon | MultiPolygon, outline: ArrayLike, T_world_base: ArrayLike, margin: float = 0.0
) -> bool:
    """True if the footprint at ``T_world_base`` lies inside ``region`` shrunk by ``margin`` [m]."""
    area = region.buffer(-margin) if margin > 0 else region
    return bool(area.contains(footprint_in_world(outline, T_world_base)))
