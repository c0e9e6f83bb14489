"""A neighbour fitted as an upright cylinder or box: the value, its prism and its distances (issue 25).

The fits (:mod:`~baseplace.world.primitive_fits`) and the acceptance test
(:mod:`~baseplace.world.fit_acceptance`) read a cluster's points in the support plane's coordinates
(:func:`~baseplace.world.neighbour_shapes.plane_frame`): x and y along the plane, z up its normal.
:class:`FittedShape` answers for those points where they lie against its solid; the whole method is
in :mod:`baseplace.world.neighbour_shapes`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.geometry.poses import FloatArray
from baseplace.world.support_plane import CLEARANCE_SIGMAS

SEGMENTS = 32
"""The cylinder's prism is its circumscribed regular polygon of this many sides (its corners lie
r (1 / cos(pi / SEGMENTS) - 1) outside it: 0.2 mm on a 4 cm bottle)."""


def noise_sigma(noise_margin: float) -> float:
    """The scene's noise sigma [m] from its noise margin n [m] (n = :data:`CLEARANCE_SIGMAS` sigma)."""
    return noise_margin / CLEARANCE_SIGMAS


@dataclass(frozen=True)
class FittedShape:
    """A neighbour object fitted as an upright cylinder or box (world frame).

    Attributes:
        kind: "cylinder" or "box".
        origin: (3,) a point on the support plane [m], the origin of ``axes``.
        axes: (3, 3) columns: two directions along the plane and its upward normal.
        centre: (2,) the axis (cylinder) or the footprint's centre (box) in plane coordinates [m].
        size: (radius,) or (half length, half width) [m], the box along ``angle`` and across.
        angle: the box's first side's direction [rad] in plane coordinates (0 for a cylinder).
        height: the top above the plane [m].
        error: u [m], the fit's own error at 3 sigma plus the acceptance's allowance
            (:mod:`~baseplace.world.fit_acceptance`).
        noise_margin: the scene's noise margin n [m].
        points: how many points it replaces.
    """

    kind: str
    origin: FloatArray
    axes: FloatArray
    centre: FloatArray
    size: tuple[float, ...]
    angle: float
    height: float
    error: float
    noise_margin: float
    points: int

    def footprint(self) -> FloatArray:
        """(K, 2) the prism's footprint polygon in plane coordinates, counter-clockwise [m]."""
        if self.kind == "cylinder":
            r = self.size[0] / math.cos(math.pi / SEGMENTS)
            a = np.linspace(0.0, 2 * math.pi, SEGMENTS, endpoint=False)
            return self.centre + r * np.c_[np.cos(a), np.sin(a)]
        c, s = math.cos(self.angle), math.sin(self.angle)
        u, v = np.array([c, s]) * self.size[0], np.array([-s, c]) * self.size[1]
        return self.centre + np.array([u + v, -u + v, -u - v, u - v])

    def vertices(self) -> FloatArray:
        """(2K, 3) the prism's corners in the world frame [m]: its footprint on the plane and at its top."""
        f = self.footprint()
        local = np.concatenate([np.c_[f, np.zeros(len(f))], np.c_[f, np.full(len(f), self.height)]])
        return np.asarray(self.origin + local @ self.axes.T, dtype=float)

    def geometry(self) -> coal.Convex:
        """The prism as a coal convex (world frame)."""
        vertices = coal.StdVec_Vec3s()
        for v in self.vertices():
            vertices.append(np.asarray(v, dtype=float))
        return coal.Convex.convexHull(vertices, False, "")

    def signed_distance(self, points: ArrayLike) -> FloatArray:
        """(N,) each point's distance [m] to the fitted solid (not the polygon), negative inside."""
        L = (np.asarray(points, dtype=float).reshape(-1, 3) - self.origin) @ self.axes
        return self.plane_signed_distance(L)

    def plane_signed_distance(self, L: FloatArray, euclidean: bool = True) -> FloatArray:
        """(N,) the signed distance [m] of points ``L`` (N, 3, plane coordinates) to the fitted solid.

        ``euclidean`` False: the largest distance outside one of its faces' planes (side, top, bottom), not
        the distance to an edge, which noise outward across both faces lengthens (by sqrt(2) at 45 deg).
        """
        t = L[:, 2]
        axial = np.maximum(t - self.height, -t)  # the bottom on the plane
        if self.kind == "cylinder":
            radial = np.hypot(L[:, 0] - self.centre[0], L[:, 1] - self.centre[1]) - self.size[0]
            out = np.c_[radial, axial]
        else:
            q = np.abs(self.box_coordinates(L)) - self.size
            out = np.c_[q, axial]
        if not euclidean:
            return np.asarray(out.max(axis=1), dtype=float)
        outside = np.linalg.norm(np.maximum(out, 0.0), axis=1)
        return np.asarray(outside + np.minimum(out.max(axis=1), 0.0), dtype=float)

    def box_coordinates(self, L: FloatArray) -> FloatArray:
        """(N, 2) the points ``L`` (plane coordinates) along a box's first side and across it, from its centre [m]."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        v = L[:, :2] - self.centre
        return np.c_[v @ [c, s], v @ [-s, c]]

    def over_footprint(self, L: FloatArray, inset: float) -> NDArray[np.bool_]:
        """(N,) the points ``L`` (plane coordinates) over the footprint shrunk by ``inset`` [m]."""
        if self.kind == "cylinder":
            v = L[:, :2] - self.centre
            return np.asarray(np.hypot(v[:, 0], v[:, 1]) <= self.size[0] - inset)
        return np.asarray(np.all(np.abs(self.box_coordinates(L)) <= np.asarray(self.size) - inset, axis=1))

    def __len__(self) -> int:
        return 1
