"""The noise of a cloud seen by direction: noise along a surface is invisible to its own plane fits.

Oracle: the noise the clouds are generated with. Seed 000's clouds carry Gaussian noise on z only;
on a vertical wall it moves the points within the wall's plane, so a plane fitted to the wall's
points sees none of it, while a horizontal surface shows all of it.
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import contact_groups
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.sensor_resolution import (
    CLEARANCE_SIGMAS,
    MIN_CLEARANCE,
    OBJECT_TOLERANCE,
    SupportPlane,
    clearance_record,
    derived_clearance,
    group_parts,
    is_fine,
)
from baseplace.world.support_plane import fit_support_slab

TABLE = 0.7
BOX = 0.05  # half side [m]
HEIGHT = 0.15


def _box_on_table(sigma_z: float, sigma_iso: float, seed: int, spacing: float = 0.01) -> np.ndarray:
    """A 1 m table top with a 10 cm box on it, walls sampled too, noise on z and on every axis."""
    rng = np.random.default_rng(seed)
    g = np.arange(-0.5, 0.5, spacing)
    X, Y = np.meshgrid(g, g)
    xy = np.c_[X.ravel(), Y.ravel()]
    on_box = np.all(np.abs(xy) <= BOX, axis=1)
    top = np.c_[xy, np.where(on_box, TABLE + HEIGHT, TABLE)]
    s, h = np.arange(-BOX, BOX, spacing), np.arange(TABLE, TABLE + HEIGHT, spacing)
    S, H = np.meshgrid(s, h)
    S, H = S.ravel(), H.ravel()
    walls = [np.c_[S, np.full_like(S, side), H] for side in (-BOX, BOX)]
    walls += [np.c_[np.full_like(S, side), S, H] for side in (-BOX, BOX)]
    p = np.concatenate([top, *walls])
    p[:, 2] += rng.normal(0.0, sigma_z, len(p))
    return p + rng.normal(0.0, sigma_iso, p.shape)


@pytest.mark.parametrize("seed", [0, 1])
def test_noise_along_z_is_seen_where_walls_hide_it(seed):
    """25 mm of z-only noise: the derived clearance is 3 sigma of 25 mm, not of what the walls show."""
    metres, note = derived_clearance(None, _box_on_table(0.025, 0.0, seed))
    assert metres / CLEARANCE_SIGMAS == pytest.approx(0.025, rel=0.2)
    assert "along z" in note and "across vertical" in note


@pytest.mark.parametrize("seed", [0, 1])
def test_isotropic_noise_is_read_as_before(seed):
    metres, _ = derived_clearance(None, _box_on_table(0.0, 0.003, seed))
    assert metres / CLEARANCE_SIGMAS == pytest.approx(0.003, rel=0.2)


def test_a_noise_free_cloud_keeps_the_floor():
    metres, note = derived_clearance(None, _box_on_table(0.0, 0.0, 0))
    assert metres == MIN_CLEARANCE and "at least 3 mm" in note


def test_the_support_planes_sigma_is_not_truncated_by_its_fit():
    """The fit keeps points within 15 mm of the densest layer (and up to half a voxel above the
    object's bottom), so larger noise is cut off there: with 25 mm of noise the residuals read
    6.8-7.7 mm (seed 000's dev scenes). Such a fit is refused (sigma above MAX_SIGMA, 5 mm; before
    session 20 some passed the 10 mm percentile test with their sigma truncated). At 5 mm, the
    band's limit, the sigma reads 4.8-5.0 mm; the derived clearance stands on the untrimmed noise
    (the surfaces' noise near the object), within 5 %."""
    for seed in range(12):
        p = _box_on_table(0.025, 0.0, seed)
        obj = GraspedObject.box([0.0, 0.0, TABLE - 0.0025 + HEIGHT / 2], [2 * BOX, 2 * BOX, HEIGHT])
        assert fit_support_slab(p, obj.footprint_distance, obj.bottom, 0.025) is None
    found = 0
    for seed in range(12):
        p = _box_on_table(0.005, 0.0, seed)
        obj = GraspedObject.box([0.0, 0.0, TABLE - 0.0025 + HEIGHT / 2], [2 * BOX, 2 * BOX, HEIGHT])
        slab = fit_support_slab(p, obj.footprint_distance, obj.bottom, 0.025)
        if slab is None:
            continue
        found += 1
        assert slab.sigma < 0.005  # the truncation this test is about
        near = p[obj.footprint_distance(p[:, :2]) <= 0.5]
        metres, note = derived_clearance(SupportPlane(slab, slab.hull, slab.points), near)
        assert metres / CLEARANCE_SIGMAS == pytest.approx(0.005, rel=0.05), note
    assert found >= 10


def _obstacle_cells_over(groups, obj, above: float) -> int:
    """Fine obstacle cells over the object's footprint (+ 12.5 mm) whose centre is ``above`` [m] over its top or higher."""
    top = obj.bottom + obj.size[2]
    n = 0
    for part in group_parts(groups.get("obstacle", ())):
        if isinstance(part, VoxelMap) and is_fine(part) and len(part):
            c = part.centres
            n += int(
                np.sum((obj.footprint_distance(c[:, :2]) <= OBJECT_TOLERANCE) & (c[:, 2] >= top + above))
            )
    return n


def test_the_objects_points_follow_the_noise_above_its_top():
    """25 mm of z-noise lifts the box's top points 10-24 mm and more above it: they are the box's (4 sigma,
    100 mm), not obstacle cells at the hand's fingertips; a bar 25 cm above the top stays an obstacle."""
    p = _box_on_table(0.025, 0.0, 3)
    obj = GraspedObject.box([0.0, 0.0, TABLE + HEIGHT / 2], [2 * BOX, 2 * BOX, HEIGHT])
    g = np.arange(-BOX, BOX, 0.01)
    bar = np.c_[g, np.zeros_like(g), np.full_like(g, TABLE + HEIGHT + 0.25)]
    p = np.concatenate([p, bar])
    voxels = VoxelMap.from_points(p)
    groups, _ = contact_groups(voxels, voxels, obj, p)
    assert _obstacle_cells_over(groups, obj, 0.0) == _obstacle_cells_over(groups, obj, 0.15) > 0
    record = clearance_record(0.075, "x", 0.075)
    assert record["object_above_top"] == pytest.approx(4 * 0.025)
    assert clearance_record(0.009, "x", 0.009)["object_above_top"] == OBJECT_TOLERANCE


def test_the_noise_is_measured_once_per_object(monkeypatch):
    """contact_groups measures the noise near the object; the clearance reuses it (about 50 ms a measurement)."""
    from baseplace.placement import pipeline
    from baseplace.world import sensor_resolution

    p = _box_on_table(0.025, 0.0, 4)
    obj = GraspedObject.box([0.0, 0.0, TABLE + HEIGHT / 2], [2 * BOX, 2 * BOX, HEIGHT])
    voxels = VoxelMap.from_points(p)
    groups, _ = contact_groups(voxels, voxels, obj, p)
    calls = []

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    real = sensor_resolution.surface_noise
    monkeypatch.setattr(sensor_resolution, "surface_noise", counted)
    monkeypatch.setattr(pipeline, "surface_noise", counted, raising=False)
    metres, note, margin = pipeline.clearance_of(groups, None, p, obj)
    assert calls == []
    assert metres == margin and metres / CLEARANCE_SIGMAS == pytest.approx(0.025, rel=0.2), note
