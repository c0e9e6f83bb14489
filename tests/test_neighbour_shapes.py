"""Neighbours fitted as whole shapes (:mod:`baseplace.world.neighbour_shapes`, issue 25).

Oracle: the true shapes (coal on them, or their densely sampled surface), never the fit's own
output. A fitted neighbour keeps c - n from its true surface (5 mm spheres 0.5 mm nearer are
refused: tests/test_clearance_bound.py runs its scenes fitted and not); a palm beyond c - n + u is
free of it; shapes that are not an upright cylinder or box (a mug with a handle, a bottle with a
band proud of its side) are rejected and stay cells, and the cells still keep c - n from them.
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest

import baseplace.world.neighbour_shapes as neighbour_shapes
from baseplace.world.neighbour_shapes import FittedShape, clusters, clusters_by_pairs, fit_neighbours
from baseplace.world.sensor_resolution import derived_clearance, group_parts
from baseplace.world.thinning import sorted_cells
from conftest import SHARED
from test_clearance_bound import PROBE, _parts, _touches
from test_clearance_from_true_surface import BOTTLE, SIGMA, TOP, noisy_scene

SEEDS = (2561, 2562, 2563)
XY = np.array([BOTTLE[0] + 0.035 + 0.05 + 0.04, BOTTLE[1]])  # 5 cm from the grasped bottle


def _side(xy, r: float, z0: float, z1: float, step: float = 0.01, top: bool = True) -> np.ndarray:
    """An upright cylinder's side (and top) points from z0 to z1, about ``step`` apart."""
    a = np.linspace(0, 2 * math.pi, max(12, math.ceil(2 * math.pi * r / step)), endpoint=False)
    A, Z = np.meshgrid(a, np.linspace(z0, z1, max(2, round((z1 - z0) / step) + 1)))
    side = np.c_[xy[0] + r * np.cos(A.ravel()), xy[1] + r * np.sin(A.ravel()), Z.ravel()]
    if not top:
        return side
    g = np.arange(-r, r + 1e-9, step)
    X, Y = np.meshgrid(g, g)
    inside = np.hypot(X, Y).ravel() <= r
    return np.concatenate(
        [side, np.c_[xy[0] + X.ravel()[inside], xy[1] + Y.ravel()[inside], np.full(inside.sum(), z1)]]
    )


def _box(lo, hi, step: float = 0.01) -> np.ndarray:
    """Points on an axis-aligned box's faces, about ``step`` apart."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    grids = [np.linspace(lo[k], hi[k], max(2, round((hi[k] - lo[k]) / step) + 1)) for k in range(3)]
    out = []
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        U, V = np.meshgrid(grids[i], grids[j])
        for value in (lo[k], hi[k]):
            q = np.empty((U.size, 3))
            q[:, i], q[:, j], q[:, k] = U.ravel(), V.ravel(), value
            out.append(q)
    return np.concatenate(out)


R, H = 0.04, 0.12
HANDLE_LO = np.array([XY[0] + R, XY[1] - 0.006, TOP + 0.03])
HANDLE_HI = np.array([XY[0] + R + 0.03, XY[1] + 0.006, TOP + 0.09])


def _mug_points() -> np.ndarray:
    """A 4 cm mug, 12 cm high, with a 3 x 1.2 x 6 cm handle out of its far side."""
    handle = _box(HANDLE_LO, HANDLE_HI)
    handle = handle[np.hypot(*(handle[:, :2] - XY).T) > R]
    return np.concatenate([_side(XY, R, TOP, TOP + H), handle])


def _mug_solids() -> list[tuple[coal.CollisionGeometry, coal.Transform3s]]:
    body = (coal.Cylinder(R, H), coal.Transform3s(np.eye(3), np.r_[XY, TOP + H / 2]))
    handle = (coal.Box(*(HANDLE_HI - HANDLE_LO)), coal.Transform3s(np.eye(3), (HANDLE_HI + HANDLE_LO) / 2))
    return [body, handle]


def _footprint(p: np.ndarray) -> np.ndarray:
    return np.hypot(*(p[:, :2] - XY).T) <= R + 0.035


def _fitted(groups) -> list[FittedShape]:
    return [part for group in groups.values() for part in group_parts(group) if isinstance(part, FittedShape)]


@pytest.mark.parametrize("seed", SEEDS)
def test_a_mug_with_a_handle_is_rejected_and_its_cells_keep_c_minus_n(seed):
    """The mug is no upright cylinder or box: not fitted; its cells refuse 5 mm spheres 0.5 mm nearer
    than c - n (= 0 at the derived default) to the true body's side away from the bottle and the true
    handle's faces."""
    groups, plane = noisy_scene(_mug_points(), _footprint, seed)
    assert plane is not None
    assert _fitted(groups) == []
    n = derived_clearance(plane)[0]
    c = n + 0.006
    parts = _parts(groups, c, None)
    bound = c - n
    solids = _mug_solids()
    probes = []
    for a in np.radians(np.arange(-60, 61, 15)):
        u = np.array([math.cos(a), math.sin(a), 0.0])
        for z in (TOP + 0.02, TOP + 0.1):
            probes.append((np.r_[XY + R * u[:2], z], u))
    for z in (TOP + 0.04, TOP + 0.06, TOP + 0.08):  # the handle's outer face and its sides
        probes.append((np.array([HANDLE_HI[0], XY[1], z]), np.array([1.0, 0.0, 0.0])))
        for s in (1.0, -1.0):
            probes.append((np.array([HANDLE_HI[0] - 0.01, XY[1] + s * 0.006, z]), np.array([0.0, s, 0.0])))
    for q, u in probes:
        sphere = coal.Sphere(PROBE)
        T = coal.Transform3s(np.eye(3), q + (bound - 0.0005 + PROBE) * u)
        true = min(
            coal.distance(sphere, T, g, Tg, coal.DistanceRequest(), coal.DistanceResult()) for g, Tg in solids
        )
        assert true <= bound - 0.0005 + 1e-4  # nearer than c - n to the true mug (its handle or body)
        assert _touches(parts, sphere, T), (
            f"a sphere {true * 1e3:.1f} mm from the true mug at {np.round(q, 3)} is free"
        )


@pytest.mark.parametrize("seed", SEEDS)
def test_shapes_that_are_no_primitive_are_rejected(seed):
    """fit_neighbours on a neighbour alone (3 mm noise, n = 9 mm): the mug, a 5 cm bottle with a 1 cm
    band 6 mm proud (narrower than a patch: the rings catch it), a bottle seen from one side and a
    4 cm bottle with a 1.5 cm neck (its neck's side lies over the footprint under the top) are
    rejected; the plain 4 cm cylinder and the 10 cm box are accepted and hold the true surface within
    u of the fitted solid (the true surface sampled every 2 mm), the cylinder's u below n."""
    from baseplace.world.support_plane import SupportSlab
    from test_clearance_bound import BOX_HALF
    from test_clearance_from_true_surface import _box_points

    hull = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    slab = SupportSlab(np.array([0.0, 0.0, TOP]), 0.01, 0.01, hull, 0.01, 10000, SIGMA)
    n = 3 * SIGMA
    rng = np.random.default_rng(seed)

    def fits(clean):
        noisy = clean + rng.normal(0.0, SIGMA, clean.shape)
        return fit_neighbours(noisy[noisy[:, 2] > TOP + n], slab, n)

    band = np.concatenate(
        [_side(XY, 0.05, TOP, TOP + 0.2), _side(XY, 0.056, TOP + 0.1, TOP + 0.11, top=False)]
    )
    one = _side(XY, 0.03, TOP, TOP + 0.2)
    one = one[(one[:, 0] - XY[0] <= 0.005) | (one[:, 2] > TOP + 0.2 - 1e-9)]
    neck = np.concatenate([_side(XY, R, TOP, TOP + 0.14), _side(XY, 0.015, TOP + 0.14, TOP + 0.2)])
    for name, clean in (("mug", _mug_points()), ("band", band), ("one side", one), ("neck", neck)):
        assert fits(clean) == [], name
    dense_cylinder = _side(XY, R, TOP, TOP + 0.2, 0.002)
    dense_box = _box([*(XY - BOX_HALF), TOP], [*(XY + BOX_HALF), TOP + 2 * BOX_HALF], 0.002)
    for name, clean, dense in (
        ("cylinder", _side(XY, R, TOP, TOP + 0.2), dense_cylinder),
        ("box", _box_points(XY, BOX_HALF), dense_box),
    ):
        found = fits(clean)
        assert len(found) == 1, name
        shape = found[0][0]
        outside = float(shape.signed_distance(dense).max())
        assert outside <= shape.error, (
            f"{name}: the true surface lies {outside * 1e3:.1f} mm outside, u {shape.error * 1e3:.1f}"
        )
        if name == "cylinder":  # a box's u exceeds n (its angle is not refined: module docstring)
            assert shape.error < n, f"{name}: u {shape.error * 1e3:.1f} mm is no better than a raw point's"


PALM = 0.0085
"""A palm is free this far [m] beyond c - n from a fitted 4.5 cm bottle (u at most 4.6 mm over ten draws,
bench/shape_fits.py; plus the fit's offset outside the true side and coal's tolerance)."""


def test_a_palm_beyond_c_minus_n_plus_u_from_a_fitted_bottle_is_free():
    """A palm-sized cube (4 cm) facing a fitted 4.5 cm neighbour bottle (three heights, three angles):
    free at c - n + PALM from the true side (on the cells it is refused there: free only from 9.5-18 mm,
    tests/test_clearance_bound.py), refused at c - n - 3 mm."""
    from test_clearance_bound import NEIGHBOURS, palms_free_beyond

    palms_free_beyond(NEIGHBOURS[1], SEEDS, PALM, fitted=1)


def test_the_clearance_note_states_each_fitted_neighbours_u():
    """The JSON's clearance note names every fitted neighbour and its u (the margin c - n + u it keeps)."""
    from baseplace.placement.pipeline import fitted_noted
    from test_clearance_bound import NEIGHBOURS

    neighbour = NEIGHBOURS[1]
    groups, _ = noisy_scene(neighbour.points, neighbour.footprint, SEEDS[0])
    (shape,) = _fitted(groups)
    c, note, n = fitted_noted(groups, (0.009, "3 sigma", 0.009))
    assert (c, n) == (0.009, 0.009)
    assert (
        note
        == f"3 sigma; 1 neighbours fitted as whole shapes, kept c - n + u: {shape.kind} u {shape.error * 1e3:.1f} mm"
    )
    unfitted = {name: g for name, g in groups.items() if not isinstance(g, FittedShape)}
    unfitted = {
        name: tuple(p for p in group_parts(g) if not isinstance(p, FittedShape))
        for name, g in unfitted.items()
    }
    assert fitted_noted(unfitted, (0.009, "3 sigma", 0.009)) == (0.009, "3 sigma", 0.009)


BUMP = 0.005
"""A feature this far [m] proud of a neighbour's side, 2 cm square: the fit's known limit."""
BUMP_SEEDS = (2570,)
"""The draw of ten (2561-2570) where that feature passes the acceptance test, tiles included, and lies
beyond u: 5.4 mm outside the fit against u 4.7 mm (the others reject it or cover it)."""


@pytest.mark.xfail(
    strict=True,
    reason="the fit's known limit (fit_acceptance's docstring): a 2 cm feature 5 mm proud can pass "
    "the acceptance test and lie beyond u (bench/shape_fits.py)",
)
def test_a_small_proud_feature_is_within_u_of_the_fitted_solid_or_rejected():
    """A 4 cm, 20 cm tall neighbour bottle with a 2 x 2 cm bump 5 mm proud of its side: either the
    acceptance test rejects it, or the fitted solid holds the whole true surface (the bump's faces
    sampled every 2 mm) within its u, so that c - n + u keeps c - n from it. The bump faces the grasped bottle."""
    lo = np.array([XY[0] - R - BUMP, XY[1] - 0.01, TOP + 0.05])
    hi = np.array([XY[0] - R + 0.002, XY[1] + 0.01, TOP + 0.07])
    bump = _box(lo, hi)
    bump = bump[bump[:, 0] < XY[0] - R]
    dense = _box(lo, hi, 0.002)
    points = np.concatenate([_side(XY, R, TOP, TOP + 0.2), bump])
    beyond = []
    for seed in BUMP_SEEDS:
        groups, _ = noisy_scene(points, _footprint, seed)
        for shape in _fitted(groups):
            outside = float(shape.signed_distance(dense).max())
            if outside > shape.error:
                beyond.append(
                    f"seed {seed}: the true surface {outside * 1e3:.1f} mm outside the fit, u {shape.error * 1e3:.1f} mm"
                )
    assert not beyond, "; ".join(beyond)


MUG = SHARED / "pointclouds" / "table_scene_mug_stereo_textured.pcd"


@pytest.mark.parametrize("seed", range(4))
def test_the_cluster_kernel_numbers_the_components_as_every_pair_does(seed, monkeypatch):
    """The compiled cell kernel against every pair within the link (a KD-tree and a sparse graph).

    Clouds of sparse blobs, dense patches and scattered points, where clusters touch and do not;
    and points exactly one link apart along a line (distances exact in floating point): joined.
    """
    monkeypatch.setattr(neighbour_shapes, "KERNEL_FROM", 0)
    rng = np.random.default_rng(seed)
    parts = [rng.normal(rng.uniform(-0.3, 0.3, 3), rng.uniform(0.005, 0.05), (rng.integers(1, 800), 3))
             for _ in range(12)]  # fmt: skip
    p = np.concatenate([*parts, rng.uniform(-0.4, 0.4, (300, 3))])[
        rng.permutation(sum(map(len, parts)) + 300)
    ]
    for link in (0.005, 0.02, 0.06):
        assert np.array_equal(clusters(p, link), clusters_by_pairs(p, link))
    utm = p + np.array([5e5, 4e6, 100.0])  # map coordinates: the cells' rounding is larger there
    assert np.array_equal(clusters(utm, 0.02), clusters_by_pairs(utm, 0.02))
    # kilometres apart: more cells than their keys hold, so every pair decides
    far = np.r_[p, p + np.array([5e6, 0.0, 0.0]), p + np.array([0.0, 0.0, -5e6])]
    assert sorted_cells(far, 0.02 / np.sqrt(3.0), 2) is None
    assert np.array_equal(clusters(far, 0.02), clusters_by_pairs(far, 0.02))
    line = np.c_[np.arange(10) * 2.0**-6, np.zeros((10, 2))]
    line[5:] += [2.0**-6 * 1e-6, 0, 0]  # one gap a hair over the link: two components
    assert clusters(line, 2.0**-6).tolist() == clusters_by_pairs(line, 2.0**-6).tolist() == [0] * 5 + [1] * 5
    empty = np.zeros((0, 3))  # no points, no grid: the pairs' way, with nothing to join
    assert sorted_cells(empty, 0.01, 1) is None
    assert clusters(empty, 0.02).tolist() == clusters_by_pairs(empty, 0.02).tolist() == []


@pytest.mark.skipif(not MUG.exists(), reason="needs the shared PCL data")
def test_the_cluster_kernel_on_the_pcl_mug_cloud():
    """Around the PCL mug (about 1 000 pairs per point within 2 cm) the kernel's components are every pair's."""
    from baseplace.terrain.io import load_cloud, load_transform

    p = load_cloud(MUG).points
    p = p[np.all(np.isfinite(p), axis=1)]
    T = load_transform("0.0162 -0.8378 -0.5458")  # z up (test_grasped_object's MUG_UP)
    p = p @ T[:3, :3].T + T[:3, 3]
    near = p[np.linalg.norm(p - [0.06, 0.605, -0.47], axis=1) < 0.08]  # the mug and the table around it
    assert len(near) >= neighbour_shapes.KERNEL_FROM
    assert np.array_equal(clusters(near), clusters_by_pairs(near))
