"""The clearance's bound c - n against the TRUE surface on sparser clouds (issue 25).

tests/test_clearance_bound.py shows the bound on clouds sampled every centimetre whose samples
include the shapes' edges. A sensor's samples do not fall on an edge: its first row lies somewhere
within one spacing of it. Here a 10 cm box and a 3 cm bottle (the neighbour of a grasped bottle on a
table) are sampled every 3, 6, 9 and 12.5 mm, the first row of samples set in from each edge by
:data:`INSET` of the spacing, without noise and with 3 mm; probe spheres of 5 mm and 1 mm radius
0.5 mm nearer than c - n to the true shape all along its edges, corners and rim (and over its
faces) must all touch the model. Oracle: coal on the true shapes (each probe's true distance);
the model's verdict is coal's collision against the scene's own parts at the security margin
Environment gives each (:func:`~baseplace.world.sensor_resolution.margin`), at the derived default
clearance (c = n: the robot does not touch).
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest

from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import contact_groups, support_plane
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.sensor_resolution import derived_clearance, derived_plane_clearance, scene_noise
from test_clearance_bound import _parts, _touches

TOP = 0.75  # the table top [m]
BOTTLE = np.array([0.0, 0.0])  # the grasped bottle's axis [m]
BOTTLE_RADIUS, BOTTLE_HEIGHT = 0.035, 0.25
HALF = 0.05  # the neighbour box: a 10 cm cube
RADIUS, HEIGHT = 0.03, 0.2  # the neighbour bottle
NEIGHBOUR = np.array([0.035 + 0.05 + 0.05, 0.0])  # 5 cm between the surfaces
SPACINGS = (0.003, 0.006, 0.009, 0.0125)
NOISES = (0.0, 0.003)
INSET = 0.35
"""The first row of samples lies this fraction of the spacing in from an edge (the last row where
the spacing leaves it)."""
SEED = 2541


def _at(dx: float, dy: float, z: float) -> np.ndarray:
    """The point ``(dx, dy)`` [m] from the neighbour's axis at height ``z``."""
    return np.array([NEIGHBOUR[0] + dx, NEIGHBOUR[1] + dy, z])


def _rows(lo: float, hi: float, step: float) -> np.ndarray:
    """Samples from ``lo`` to ``hi`` every ``step``, the first :data:`INSET` of a step in from ``lo``."""
    return np.arange(lo + INSET * step, hi, step)


def _box(xy: np.ndarray, half: float, step: float) -> np.ndarray:
    """A box's top and four sides standing on the table, sampled every ``step`` (no sample on an edge)."""
    g = _rows(-half, half, step)
    A, B = np.meshgrid(g, g)
    S, Z = np.meshgrid(g, TOP + 2 * half - _rows(0.0, 2 * half, step))  # the top row INSET below the edge
    parts = [np.c_[xy[0] + A.ravel(), xy[1] + B.ravel(), np.full(A.size, TOP + 2 * half)]]
    for sgn in (-1, 1):
        parts.append(np.c_[xy[0] + S.ravel(), np.full(S.size, xy[1] + sgn * half), Z.ravel()])
        parts.append(np.c_[np.full(S.size, xy[0] + sgn * half), xy[1] + S.ravel(), Z.ravel()])
    return np.concatenate(parts)


def _cylinder(xy: np.ndarray, r: float, height: float, step: float) -> np.ndarray:
    """A bottle's side and top sampled every ``step``: its rows end below the rim, its top's grid
    inside it (no sample on the rim)."""
    n = max(12, math.ceil(2 * math.pi * r / step))
    rows = TOP + height - _rows(0.0, height, step)  # the top row INSET below the rim
    a, z = np.meshgrid(np.linspace(0, 2 * math.pi, n, endpoint=False), rows)
    side = np.c_[xy[0] + r * np.cos(a.ravel()), xy[1] + r * np.sin(a.ravel()), z.ravel()]
    g = _rows(-r, r, step)
    X, Y = np.meshgrid(g, g)
    inside = np.hypot(X, Y).ravel() <= r - INSET * step
    top = np.c_[xy[0] + X.ravel()[inside], xy[1] + Y.ravel()[inside], np.full(inside.sum(), TOP + height)]
    return np.concatenate([side, top])


class Shape:
    """The true neighbour (coal), its samples, and probes on its surface."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        if kind == "box":
            self.geometry: coal.CollisionGeometry = coal.Box(2 * HALF, 2 * HALF, 2 * HALF)
            self.T = coal.Transform3s(np.eye(3), np.r_[NEIGHBOUR, TOP + HALF])
        else:
            self.geometry = coal.Cylinder(RADIUS, HEIGHT)
            self.T = coal.Transform3s(np.eye(3), np.r_[NEIGHBOUR, TOP + HEIGHT / 2])

    def samples(self, step: float) -> np.ndarray:
        if self.kind == "box":
            return _box(NEIGHBOUR, HALF, step)
        return _cylinder(NEIGHBOUR, RADIUS, HEIGHT, step)

    def footprint(self, p: np.ndarray) -> np.ndarray:
        """(N,) True for the table's points (N, 3) under the neighbour."""
        if self.kind == "box":
            return np.all(np.abs(p[:, :2] - NEIGHBOUR) <= HALF, axis=1)
        return np.hypot(*(p[:, :2] - NEIGHBOUR).T) <= RADIUS

    def probes(self, where: str) -> list[tuple[np.ndarray, np.ndarray]]:
        """(point on the true surface, outward unit direction in its normal cone) on the edges, corners
        and rim (``where`` "edges") or on the faces ("faces"), all around."""
        out: list[tuple[np.ndarray, np.ndarray]] = []
        if self.kind == "box":
            top = TOP + 2 * HALF
            g = np.linspace(-HALF, HALF, 21)
            zs = np.linspace(TOP + 0.02, top, 17)
            for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                for z in zs:  # the vertical edges, up to the corner
                    q = _at(sx * HALF, sy * HALF, z)
                    for t in np.linspace(0, 1, 5):
                        u = np.array([sx * math.cos(t * math.pi / 2), sy * math.sin(t * math.pi / 2), 0.0])
                        if where == "edges":
                            out.append((q, u))
                        corner = [np.r_[u[:2], 1.0], np.r_[u[:2], 0.4]] if z == top else []
                        out += [(q, c / np.linalg.norm(c)) for c in corner if where == "edges"]
            for s in (1, -1):
                for x in g:  # the top edges
                    for v in ((s, 0), (0, s)):
                        q = _at(HALF * s, x, top) if v[0] else _at(x, HALF * s, top)
                        for t in np.linspace(0, 1, 5):
                            u = np.r_[np.array(v) * math.cos(t * math.pi / 2), math.sin(t * math.pi / 2)]
                            if where == "edges":
                                out.append((q, u))
            if where == "faces":
                for x in g[2:-2]:
                    for y in g[2:-2:2]:
                        out.append((_at(x, y, top), np.array([0.0, 0.0, 1.0])))
                    for z in zs[:-2:2]:
                        for s in (1, -1):
                            out.append((_at(s * HALF, x, z), np.array([s, 0.0, 0.0])))
                            out.append((_at(x, s * HALF, z), np.array([0.0, s, 0.0])))
            return out
        top = TOP + HEIGHT
        for a in np.radians(np.arange(0, 360, 5)):
            w = np.array([math.cos(a), math.sin(a), 0.0])
            rim = np.r_[NEIGHBOUR + RADIUS * w[:2], top]
            if where == "edges":
                for t in np.linspace(0, 1, 5):
                    out.append((rim, math.cos(t * math.pi / 2) * w + [0.0, 0.0, math.sin(t * math.pi / 2)]))
            else:
                for z in np.linspace(TOP + 0.02, top - 0.005, 12):
                    out.append((np.r_[NEIGHBOUR + RADIUS * w[:2], z], w))
                for f in (0.0, 0.5, 0.9):
                    out.append((np.r_[NEIGHBOUR + f * RADIUS * w[:2], top], np.array([0.0, 0.0, 1.0])))
        return out


SHAPES = {"box": Shape("box"), "bottle": Shape("bottle")}


@pytest.fixture(scope="module", params=[(k, s, n, f) for k in SHAPES for s in SPACINGS for n in NOISES for f in (False, True)],
                ids=lambda p: f"{p[0]}-{p[1] * 1e3:g}mm-noise{p[2] * 1e3:g}mm{'-fitted' if p[3] else ''}")  # fmt: skip
def scene(request):
    """The grasped bottle on a table beside the neighbour, all sampled every ``step``, with ``noise``:
    (neighbour, parts as Environment checks them, c, n). ``-fitted``: the neighbour may be fitted as a
    whole shape (:mod:`baseplace.world.neighbour_shapes`, the default), else it stays cells."""
    kind, step, noise, fit_shapes = request.param
    shape = SHAPES[kind]
    g = np.arange(-0.3 + INSET * step, 0.3, step)
    X, Y = np.meshgrid(g, g)
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, TOP)]
    table = table[(np.hypot(*(table[:, :2] - BOTTLE).T) > BOTTLE_RADIUS) & ~shape.footprint(table)]
    bottle = _cylinder(BOTTLE, BOTTLE_RADIUS, BOTTLE_HEIGHT, step)
    clean = np.concatenate([table, bottle, shape.samples(step)])
    points = clean + np.random.default_rng(SEED).normal(0.0, noise, clean.shape)
    voxels = VoxelMap.from_points(points)
    grasped = GraspedObject.cylinder([*BOTTLE, TOP + BOTTLE_HEIGHT / 2], BOTTLE_RADIUS, BOTTLE_HEIGHT)
    groups, _ = contact_groups(voxels, voxels, grasped, points, fit_shapes=fit_shapes)
    plane = support_plane(groups)
    assert plane is not None
    n, _ = derived_clearance(plane, noise=scene_noise(groups))
    c = n  # the derived default: c - n = 0
    return shape, _parts(groups, c, derived_plane_clearance(plane, scene_noise(groups))[0]), c, n


KNOWN_HOLE = {
    "box-9mm-noise0mm-edges-5mm", "box-9mm-noise0mm-edges-1mm", "box-12.5mm-noise0mm-edges-5mm",
    "box-12.5mm-noise0mm-edges-1mm", "box-12.5mm-noise0mm-faces-5mm", "box-12.5mm-noise3mm-edges-1mm",
    "bottle-12.5mm-noise0mm-edges-1mm", "bottle-12.5mm-noise3mm-faces-5mm",
}  # fmt: skip
"""The cases the cells model fails (docs/placement.md, "A known limit: sparse clouds"): expected to fail,
strictly, with every assert run. With the neighbour fitted as a whole shape (the ``-fitted`` cases)
all pass. A fix that closes one makes it pass, which fails the suite until the
case leaves this set; a case that starts failing outside it fails the suite as any test does."""


@pytest.mark.parametrize("where, probe", [("edges", 0.005), ("edges", 0.001), ("faces", 0.005)],
                         ids=["edges-5mm", "edges-1mm", "faces-5mm"])  # fmt: skip
def test_spheres_nearer_than_c_minus_n_to_the_true_shape_touch_the_model(scene, where, probe, request):
    if request.node.callspec.id in KNOWN_HOLE:
        request.applymarker(
            pytest.mark.xfail(strict=True, reason="the sparse-cloud hole of the clearance bound")
        )
    shape, parts, c, n = scene
    bound = c - n
    free = []
    for q, u in shape.probes(where):
        sphere = coal.Sphere(probe)
        T = coal.Transform3s(np.eye(3), q + (bound - 0.0005 + probe) * u)
        true = coal.distance(
            sphere, T, shape.geometry, shape.T, coal.DistanceRequest(), coal.DistanceResult()
        )
        assert true == pytest.approx(bound - 0.0005, abs=1e-4)
        if not _touches(parts, sphere, T):
            free.append(np.round(q - [*NEIGHBOUR, TOP], 4))
    assert not free, (
        f"{len(free)} spheres {(bound - 0.0005) * 1e3:.1f} mm from the true {shape.kind} (c - n = {bound * 1e3:.1f} mm, "
        f"n = {n * 1e3:.1f} mm) are free, e.g. at {free[: min(3, len(free))]} (from its base's centre)"
    )
