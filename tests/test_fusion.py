"""OctoMap fusion of posed clouds; the navigation grid as scene points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.sim.camera import CameraSettings, depth_cloud, look_at
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.fusion import FusionSettings, PosedCloud, fuse_clouds
from baseplace.terrain.io import load_cloud
from baseplace.world.grid_scene import grid_points
from baseplace.world.occupancy import OccupancyGrid
from baseplace_experiments.fusion_experiment import fusion_trial


def _wall_and_floor(rng: np.random.Generator, transient: bool, n: int = 40_000) -> np.ndarray:
    floor = np.c_[rng.uniform(-1, 1, (n, 2)), np.zeros(n)]
    if not transient:
        return floor
    wall = np.c_[np.full(800, 0.0), rng.uniform(-0.5, 0.5, 800), rng.uniform(0.05, 1.0, 800)]
    return np.vstack([floor, wall])


def test_views_that_see_through_a_transient_wall_clear_it():
    rng = np.random.default_rng(0)
    first = PosedCloud(_wall_and_floor(rng, True), np.array([-1.5, 0.0, 1.2]))  # a wall at x = 0 in the way
    others = [PosedCloud(_wall_and_floor(rng, False), np.array([1.5, y, 1.2])) for y in (-0.3, 0.3)]
    # rays from x = 1.5, z = 1.2 to the floor beyond x = -0.5 cross the wall below z = 0.3
    on_wall = lambda p: (np.abs(p[:, 0]) < 0.04) & (p[:, 2] > 0.1) & (p[:, 2] < 0.3)  # noqa: E731
    # octomap updates a voxel once per scan: a hit (0.7) and two misses (0.4) leave it occupied (0.51) ...
    kept = fuse_clouds([first, *others], FusionSettings())
    assert on_wall(kept).sum() > 100
    # ... two misses of 0.35 make it free (0.40): the wall the other views see through is gone
    cleared = fuse_clouds([first, *others], FusionSettings(prob_miss=0.35))
    assert on_wall(cleared).sum() < 0.1 * on_wall(kept).sum()
    floor = np.abs(cleared[:, 2] - 0.0125) < 0.02
    assert floor.sum() > 0.8 * (np.abs(kept[:, 2] - 0.0125) < 0.02).sum()  # the floor stays
    with pytest.raises(InputError, match="at least one cloud"):
        fuse_clouds([])


def test_fused_octomap_is_written_and_read_back(tmp_path):
    rng = np.random.default_rng(1)
    cloud = PosedCloud(_wall_and_floor(rng, False), np.array([0.0, 0.0, 1.0]))
    out = tmp_path / "fused.bt"
    points = fuse_clouds([cloud], save=out)
    np.testing.assert_allclose(np.sort(load_cloud(out).points, axis=0), np.sort(points, axis=0))


def test_camera_returns_lie_on_the_scene_surface():
    rng = np.random.default_rng(2)
    scene = generate_scene(
        SceneSettings(size_class="small", n_planes=1, extent=(4.0, 4.0), with_box=False), rng
    )
    T = look_at([1.5, 0.0, 1.5], [0.0, 0.0, 0.0])
    pts = depth_cloud(scene, T, rng, CameraSettings(width=80, height=60, outliers=0.0, wall_height=0.0))
    world = pts @ T[:3, :3].T + T[:3, 3]
    err = world[:, 2] - scene.height(world[:, :2])
    ranges = np.linalg.norm(pts, axis=1)
    sigma = 0.0012 + 0.0019 * (ranges - 0.4) ** 2  # the noise model along the ray bounds the height error
    assert np.mean(np.abs(err) <= 4 * sigma + 0.01) > 0.97
    assert np.all(pts[:, 2] > 0)  # in front of the camera (optical frame: z forward)


@pytest.mark.slow  # ~15 s: three rendered views and two OctoMaps
def test_fused_map_segments_at_least_as_well_as_the_union():
    row, _, _ = fusion_trial("small", 7, True, CameraSettings(width=160, height=120))
    assert row["fused"]["accuracy"] >= row["union"]["accuracy"]
    assert row["fused_miss_0.35"]["accuracy"] >= row["union"]["accuracy"]
    assert row["fused_miss_0.35"]["voxels_above_surface"] < row["union"]["voxels_above_surface"]


def test_grid_points_floor_columns_and_the_cameras_view():
    data = np.zeros((10, 10), dtype=np.int8)
    data[5, 5] = 100  # an occupied cell at x, y in [0.5, 0.6)
    data[0, :] = -1  # the bottom row unknown
    data[8, 8] = 100  # an occupied cell the camera sees
    grid = OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0))
    seen = np.array([[0.85, 0.85, 0.7]])
    pts = grid_points(grid, (0.0, 0.0, 1.0, 1.0), 0.025, seen=seen)
    floor = pts[pts[:, 2] == 0]
    assert not np.any(floor[:, 1] < 0.1)  # unknown cells: no floor
    column = pts[(np.abs(pts[:, 0] - 0.55) < 0.05) & (np.abs(pts[:, 1] - 0.55) < 0.05)]
    assert column[:, 2].min() > 0 and column[:, 2].max() > 1.9  # occupied: a 2 m column, no floor
    in_seen = (np.abs(pts[:, 0] - 0.85) < 0.05) & (np.abs(pts[:, 1] - 0.85) < 0.05)
    assert not in_seen.any()  # the camera's cell comes from the camera: no column, no floor
    # free floor: 1 m^2 less the unknown row and the two occupied cells
    assert math.isclose(len(floor) * 0.025**2, 1.0 - 0.1 - 0.01 - 0.01, rel_tol=1e-9)
