from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from baseplace.errors import InputError, NothingFoundError
from baseplace.geometry.poses import BasePose
from baseplace.placement.surface_map import (
    FACE_NUDGE,
    allowed_bins,
    build_surface_map,
    parse_polygon,
    surface_grid,
)
from baseplace.placement.surface_sampling import SurfaceSampler, discount
from baseplace.placement.surface_storage import load_surface_map, save_surface_map
from baseplace.planning.attachments import grounding, reachability
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.terrain.polygons import footprint_in_world, footprint_outline
from baseplace.world.occupancy import OccupancyGrid

TABLE = "0,0;1.4,0;1.4,0.65;0,0.65"


@pytest.fixture(scope="module")
def pr2_maps(pr2):
    return {arm: build_map(pr2, arm, BuildSettings(samples=1_000_000, seed=5)) for arm in ("left", "right")}


@pytest.fixture(scope="module")
def table_map(pr2, pr2_maps):
    return build_surface_map(pr2, {"right": pr2_maps["right"]}, TABLE, 0.74, resolution=0.1, orientations=8)


def _naive_surface_map(rmap, smap):
    """Eq. 2 by a loop over surface points and base cells, with R_P read from the map's raw cells."""
    grid = rmap.grid
    allowed = allowed_bins(rmap, smap.cone)
    reached = np.zeros((grid.n_voxels, grid.n_orientations), dtype=bool)
    voxel, orient = np.divmod(rmap.cells, grid.n_orientations)
    reached[voxel, orient] = True
    voxel_ok = (reached & allowed).any(axis=1)
    pts = surface_grid(smap.polygon, smap.resolution)
    out = np.zeros_like(smap.values)
    _, nx, ny = out.shape
    for t, theta in enumerate(smap.thetas):
        for i in range(nx):
            for j in range(ny):
                x, y = smap.origin[0] + i * smap.resolution, smap.origin[1] + j * smap.resolution
                T_base_world = np.linalg.inv(BasePose(x, y, float(theta)).matrix())
                p = (
                    T_base_world
                    @ np.c_[pts, np.full(len(pts), smap.height + smap.tcp_height), np.ones(len(pts))].T
                )[:3].T
                ijk = np.floor((p - np.asarray(grid.origin)) / grid.voxel_size + FACE_NUDGE).astype(int)
                inside = np.all((ijk >= 0) & (ijk < np.asarray(grid.shape)), axis=1)
                flat = np.ravel_multi_index(ijk[inside].T, grid.shape)
                out[t, i, j] = voxel_ok[flat].sum() / len(pts)
    return out


def test_fft_accumulation_matches_the_loop_over_points(pr2, pr2_maps, table_map):
    naive = _naive_surface_map(pr2_maps["right"], table_map)
    valid = table_map.values > 0
    assert valid.sum() > 100
    # where the pose is valid the FFT correlation equals the loop; elsewhere the map is 0
    np.testing.assert_allclose(table_map.values[valid], naive[valid], atol=1e-5)
    assert (naive[~valid] > 0).sum() > 0  # some reachable poses were invalidated (over the furniture)


def test_poses_over_the_furniture_are_zero(pr2, table_map):
    poses, values = table_map.cell_poses()
    assert len(poses) > 0 and np.all(values > 0)
    outline = footprint_outline(pr2.spec.footprint_radius, pr2.spec.footprint_polygon)
    table = shapely.Polygon(parse_polygon(TABLE))
    for p in poses[:: max(1, len(poses) // 300)]:
        assert not footprint_in_world(outline, BasePose(*p).matrix()).intersects(table)


def test_arm_combination_is_max_and_min(pr2, pr2_maps):
    kw = {"resolution": 0.1, "orientations": 8}
    left = build_surface_map(pr2, {"left": pr2_maps["left"]}, TABLE, 0.74, **kw).values
    right = build_surface_map(pr2, {"right": pr2_maps["right"]}, TABLE, 0.74, **kw).values
    both = build_surface_map(pr2, pr2_maps, TABLE, 0.74, combine="both", **kw).values
    either = build_surface_map(pr2, pr2_maps, TABLE, 0.74, combine="any", **kw).values
    np.testing.assert_array_equal(either, np.maximum(left, right))
    np.testing.assert_array_equal(both, np.minimum(left, right))
    assert (left != right).any()


def test_surface_map_agrees_with_ik_ground_truth(pr2):
    """R_S against the share of table points that IK reaches (an independent oracle)."""
    from baseplace_experiments.surface_truth import SurfaceTruth

    rmap = build_map(pr2, "right", BuildSettings(samples=10_000_000, seed=1))
    smap = build_surface_map(pr2, {"right": rmap}, "0,0;0.6,0;0.6,0.4;0,0.4", 0.74, resolution=0.05)
    truth = SurfaceTruth(pr2, "right", smap, orientations=4, restarts=6)
    rng = np.random.default_rng(0)
    poses, values = smap.cell_poses()
    pick = rng.choice(len(poses), 8, replace=False)
    errors = [abs(values[k] - truth.share(poses[k], rng)) for k in pick]
    assert np.mean(errors) <= 0.15


def test_storage_round_trip_and_corruption(table_map, tmp_path):
    path = tmp_path / "t.smap"
    size = save_surface_map(table_map, path)
    assert 0 < size < 200_000
    back = load_surface_map(path)
    np.testing.assert_allclose(back.values, table_map.values, atol=2e-5)
    assert (back.values > 0).sum() == (table_map.values > 0).sum()
    assert back.summary() | {"max": 0} == table_map.summary() | {"max": 0}
    data = bytearray(path.read_bytes())
    (tmp_path / "cut.smap").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="corrupt"):
        load_surface_map(tmp_path / "cut.smap")
    with pytest.raises(InputError, match="does not exist"):
        load_surface_map(tmp_path / "none.smap")


@pytest.mark.parametrize(
    ("polygon", "fragment"),
    [
        ("0,0;1,1;1,0;0,1", "not simple"),  # a bow tie
        ("0,0;1,0;2,0", "degenerate"),
        ("0,0;1,0", "at least 3"),
        ("0,0;1;x,2", "x1,y1;x2,y2"),
    ],
)
def test_bad_polygons(polygon, fragment):
    with pytest.raises(InputError, match=fragment):
        parse_polygon(polygon)


def test_bad_arguments(pr2, pr2_maps):
    with pytest.raises(InputError, match="valid: any, both"):
        build_surface_map(pr2, pr2_maps, TABLE, 0.74, combine="all")
    with pytest.raises(InputError, match="height"):
        build_surface_map(pr2, pr2_maps, TABLE, -1.0)
    with pytest.raises(InputError, match="no grid point"):
        build_surface_map(pr2, pr2_maps, "0.01,0.01;0.02,0.01;0.02,0.02", 0.74, resolution=0.1)
    with pytest.raises(InputError, match="built for"):
        build_surface_map(pr2, {"left": pr2_maps["right"]}, TABLE, 0.74)


def test_discount_follows_eq_3():
    prev = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    c = np.array([[0.25, 0.0, 0.0], [3.0, 3.0, 0.0], [0.0, 0.0, math.pi / 8], [0.0, 0.0, 2 * math.pi]])
    w = discount(c, prev)
    # d = |0.25|/0.5 = 0.5 to the first, 0.75/0.5 > 1 to the second; far away: 1; pi/8 over pi/4: 0.5
    np.testing.assert_allclose(w, [0.5, 1.0, 0.5, 0.0], atol=1e-12)


def test_discounted_samples_spread_and_stay_reachable(pr2, table_map):
    rng = np.random.default_rng(1)
    spread = {}
    for discounted in (False, True):
        sampler = SurfaceSampler(table_map, pr2, candidates=20, discounted=discounted)
        samples = np.array([[s.pose.x, s.pose.y] for s in (sampler.sample(rng) for _ in range(25))])
        assert np.all(table_map.reachability(np.c_[samples, [s.pose.yaw for s in sampler.history]]) > 0)
        d = np.linalg.norm(samples[:, None] - samples[None], axis=-1)
        spread[discounted] = d[np.triu_indices(len(d), 1)].mean()
    assert spread[True] > 1.2 * spread[False]


def _occupancy(free_box: tuple[float, float, float, float] | None) -> OccupancyGrid:
    res = 0.05
    data = np.full((80, 100), 100, dtype=np.int8)  # 5 m x 4 m from (-1.5, -1.5)
    if free_box is not None:
        x0, y0, x1, y1 = free_box
        cols = slice(int((x0 + 1.5) / res), int((x1 + 1.5) / res))
        rows = slice(int((y0 + 1.5) / res), int((y1 + 1.5) / res))
        data[rows, cols] = 0
    return OccupancyGrid(data, res, (-1.5, -1.5, 0.0), None)


def test_occupancy_limits_the_samples(pr2, table_map):
    grid = _occupancy((-1.5, -1.5, 3.5, 0.0))  # free only below the table (y < 0)
    sampler = SurfaceSampler(table_map, pr2, grid, candidates=10)
    rng = np.random.default_rng(2)
    for _ in range(10):
        s = sampler.sample(rng)
        assert grid.value_at(np.array([[s.pose.x, s.pose.y]]))[0] == 0
        assert grid.clearance(np.array([[s.pose.x, s.pose.y]]))[0] > pr2.spec.footprint_bounding_radius
    with pytest.raises(InputError, match="leaves no free pose"):
        SurfaceSampler(table_map, pr2, _occupancy(None))


def test_nothing_found_when_every_draw_fails(pr2, table_map):
    sampler = SurfaceSampler(table_map, pr2, candidates=5, max_draws=256)
    sampler._collides = lambda pose: True  # type: ignore[method-assign]
    with pytest.raises(NothingFoundError, match="no valid pose"):
        sampler.sample(np.random.default_rng(0))


def test_attachments(pr2, table_map):
    poses = grounding(table_map, np.random.default_rng(3), robot=pr2, candidates=10)
    first, second = next(poses), next(poses)
    assert reachability(table_map, (first.pose.x, first.pose.y, first.pose.yaw)) == pytest.approx(
        first.reachability
    )
    assert (
        math.hypot(first.pose.x - second.pose.x, first.pose.y - second.pose.y) > 0.1
        or abs(first.pose.yaw - second.pose.yaw) > 0.3
    )
    assert reachability(table_map, (0.7, 0.3, 0.0)) == 0.0  # standing in the table
