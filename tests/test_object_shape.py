"""The grasped object as a fitted whole shape where nothing may touch it (the transit), its cells where the hand may.

A bottle's noisy rim keeps the whole clearance c from its raw cells, so a top-down pre-grasp had
to stand about c above the measured rim. Fitted and accepted as a neighbour is
(:mod:`baseplace.world.neighbour_shapes`), the object keeps c - n + u in the transit
(:func:`~baseplace.world.sensor_resolution.object_obstacle`); at the grasp and in the approach the
hand still meets the cells (:func:`~baseplace.world.sensor_resolution.object_contact`). The
oracle: the true cylinder and coal.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest

from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import contact_groups, support_plane
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.neighbour_shapes import FittedShape
from baseplace.world.sensor_resolution import (
    derived_clearance,
    group_parts,
    margin,
    object_contact,
    object_obstacle,
)
from test_clearance_from_true_surface import BOTTLE, HEIGHT, RADIUS, SIGMA, TOP, _cylinder_points
from test_neighbour_shapes import _mug_points

SEEDS = (4101, 4102, 4103)
PROBE = 0.005
"""A fingertip-sized sphere [m]."""


def _grasped(clean: np.ndarray, grasped: GraspedObject, seed: int, fit_shapes: bool = True):
    """(the grasped object's group, c = n, the exact plane) of ``clean`` points on a table, with noise."""
    rng = np.random.default_rng(seed)
    X, Y = np.meshgrid(np.arange(-0.4, 0.4, 0.01), np.arange(-0.4, 0.4, 0.01))
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, TOP)]
    table = table[grasped.footprint_distance(table[:, :2]) > 0.0]
    points = np.concatenate([table, clean]) + rng.normal(0.0, SIGMA, (len(table) + len(clean), 3))
    voxels = VoxelMap.from_points(points)
    groups, object_group = contact_groups(voxels, voxels, grasped, points, fit_shapes=fit_shapes)
    plane = support_plane(groups)
    assert plane is not None and object_group is not None
    return object_group, derived_clearance(plane)[0], plane


def _bottle() -> GraspedObject:
    return GraspedObject.cylinder([*BOTTLE, TOP + HEIGHT / 2], RADIUS, HEIGHT)


def _kept(group, clearance: float) -> list[tuple[coal.CollisionGeometry, float]]:
    """(geometry, security margin) of each part of a grasped object's group, as Environment checks them."""
    out = []
    for part in group_parts(group):
        if isinstance(part, FittedShape):
            out.append((part.geometry(), margin(part, clearance)))
        elif len(part):
            octree = coal.makeOctree(np.ascontiguousarray(part.centres), part.resolution)
            out.append((octree, margin(part, clearance)))
    return out


def _touches(kept, centre: np.ndarray) -> bool:
    request = coal.CollisionRequest()
    T = coal.Transform3s(np.eye(3), centre)
    for geometry, m in kept:
        request.security_margin = m
        if coal.collide(coal.Sphere(PROBE), T, geometry, coal.Transform3s(), request, coal.CollisionResult()):
            return True
    return False


@pytest.mark.parametrize("seed", SEEDS)
def test_a_bottle_is_fitted_for_the_transit_and_keeps_its_cells_for_the_hand(seed):
    """The grasped bottle's group leads with an accepted cylinder, the true one within u of it; the
    hand's group is the same cells as without the fit."""
    group, n, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), seed)
    shape = object_obstacle(group)
    assert isinstance(shape, FittedShape) and shape.kind == "cylinder"
    true = _cylinder_points(BOTTLE, step=0.002, rim_row=True)
    assert float(shape.signed_distance(true).max()) <= shape.error  # the true surface within u of the fit
    assert shape.error < n  # a whole shape knows its surface better than a raw point
    cells = object_contact(group)
    assert not any(isinstance(p, FittedShape) for p in group_parts(cells))
    unfitted, _, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), seed, fit_shapes=False)
    assert [type(p) for p in group_parts(unfitted)] == [type(p) for p in group_parts(cells)]
    for a, b in zip(group_parts(unfitted), group_parts(cells), strict=True):
        assert np.array_equal(a.keys, b.keys)


@pytest.mark.parametrize("seed", SEEDS)
def test_over_the_top_a_fingertip_is_free_nearer_than_on_the_cells_and_refused_within_c_minus_n(seed):
    """Over the true top (its middle, and 2.5 and 3.2 cm out), a fingertip 2u above it is free of the
    transit's object (5-6.75 mm would do: the fit's top within u of the true one, plus u) and touches
    the cells (free from 12.25-17 mm: the measured rim and top keep c); 0.5 mm nearer than c - n
    (= 0: touching) it is refused."""
    group, n, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), seed)
    c = n  # the default
    shape = object_obstacle(group)
    assert isinstance(shape, FittedShape)
    transit, cells = _kept(shape, c), _kept(object_contact(group), c)
    top = np.array([*BOTTLE, TOP + HEIGHT])
    for dx in (0.0, 0.025, 0.032):
        above = top + np.array([dx, 0.0, PROBE + 2 * shape.error])
        assert not _touches(transit, above), (
            f"refused at 2u = {2 * shape.error * 1e3:.1f} mm above the true top"
        )
        assert _touches(cells, above)  # the cells keep c (9 mm) from the noisy top
        assert _touches(transit, top + np.array([dx, 0.0, PROBE + (c - n) - 0.0005]))


@pytest.mark.parametrize("seed", SEEDS)
def test_around_the_true_side_the_fitted_object_refuses_what_c_minus_n_refuses(seed):
    """At twelve angles and two heights, a fingertip 0.5 mm nearer than c - n (= 0) to the true side
    touches the transit's object: the fit never lets the transit into the true bottle."""
    group, n, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), seed)
    transit = _kept(object_obstacle(group), n)
    for a in np.radians(np.arange(0, 360, 30)):
        u = np.array([np.cos(a), np.sin(a), 0.0])
        for z in (TOP + 0.05, TOP + 0.2):
            centre = np.array([*BOTTLE, z]) + (RADIUS + PROBE - 0.0005) * u
            assert _touches(transit, centre), f"free at {np.degrees(a):.0f} deg, z {z:.2f}"


def test_a_mug_with_a_handle_keeps_its_cells_in_the_transit():
    """No upright cylinder or box holds all the mug's points: the transit keeps the cells."""
    mug = GraspedObject.from_points(_mug_points())  # test_neighbour_shapes' mug, grasped here
    group, _, _ = _grasped(_mug_points(), mug, SEEDS[0])
    assert not any(isinstance(p, FittedShape) for p in group_parts(group))
    assert object_obstacle(group) is group


def test_the_clearance_note_names_the_objects_shape_and_its_u():
    """The JSON's clearance note states the object's fitted shape and u (the margin it keeps in the transit)."""
    from baseplace.placement.pipeline import fitted_noted

    group, n, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), SEEDS[0])
    shape = object_obstacle(group)
    assert isinstance(shape, FittedShape)
    kept = (n, "3 sigma", n)
    assert fitted_noted({}, kept, group) == (
        n,
        f"3 sigma; the grasped object fitted as a cylinder (u {shape.error * 1e3:.1f} mm), kept c - n + u in the transit",
        n,
    )
    unfitted, _, _ = _grasped(_cylinder_points(BOTTLE), _bottle(), SEEDS[0], fit_shapes=False)
    assert fitted_noted({}, kept, unfitted) == kept
