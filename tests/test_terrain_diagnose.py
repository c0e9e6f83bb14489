"""Segmentation of real clouds at default settings; up-direction checks; the causes of no support."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.cli import main
from baseplace.errors import InputError
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.diagnose import auto_resolution, check_up_direction, dominant_planes
from baseplace.terrain.io import load_cloud, load_transform
from baseplace.terrain.pipeline import terrain_from_points
from conftest import SHARED

CLOUDS = SHARED / "pointclouds"
MUG = CLOUDS / "table_scene_mug_stereo_textured.pcd"
OFFICE = CLOUDS / "office1.pcd"
# The PCL tabletop's reference plane in the camera frame (n . p + d = 0), from a RANSAC fit.
MUG_NORMAL, MUG_D = np.array([-0.0162, 0.8378, 0.5458]), -0.5287
OFFICE_UP = np.array([-0.0361, -0.9991, -0.0217])  # the floor normal from a RANSAC fit (docs)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(min(1.0, c)))


def test_mug_table_at_default_settings_through_the_cli(capsys):
    code = main(["segment", str(MUG), "--transform", "0.0162 -0.8378 -0.5458", "--json"])
    assert code == 0
    import json

    result = json.loads(capsys.readouterr().out)
    assert result["resolution"] <= 0.03  # chosen from the 1.5 m view, not seed 000's 5 cm
    T = load_transform("0.0162 -0.8378 -0.5458")
    # the region's plane back in the camera frame: n_cam = R^T n_world, d unchanged (no translation)
    best = None
    for r in result["regions"]:
        n_cam = T[:3, :3].T @ np.array(r["normal"])
        err = _angle_deg(n_cam, MUG_NORMAL)
        d_cam = r["d"] * float(np.sign(n_cam @ MUG_NORMAL))
        if best is None or err < best[0]:
            best = (err, d_cam, r["area_m2"])
    assert best is not None
    err, d_cam, area = best
    assert err < 1.0
    assert d_cam == pytest.approx(MUG_D, abs=0.01)
    assert 0.1 < area < 0.3  # the table in view, about 0.6 x 0.4 m less the mug and the image edge


def test_mug_at_five_cm_says_too_small_and_what_to_try(capsys):
    code = main(["segment", str(MUG), "--transform", "0.0162 -0.8378 -0.5458", "--resolution", "0.05"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "too small" in err and "--resolution 0.02" in err


def test_office_without_transform_is_flagged_with_the_up_vector(capsys):
    code = main(["segment", str(OFFICE)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "does not look z-up" in err
    up = np.array([float(v) for v in err.split('--transform "')[1].split('"')[0].split()])
    assert _angle_deg(up, OFFICE_UP) < 5.0 and up @ OFFICE_UP > 0


def test_office_with_the_documented_transform_floor_and_desk():
    cloud = load_cloud(OFFICE).transformed(load_transform("-0.0361 -0.9991 -0.0217"))
    regions = terrain_from_points(cloud.points).segmentation.regions
    floor = min((r for r in regions if r.area > 1.0), key=lambda r: r.centroid[2])
    assert floor.centroid[2] == pytest.approx(-1.466, abs=0.05)  # the RANSAC floor (docs)
    above = [r.centroid[2] - floor.centroid[2] for r in regions if r.area > 0.2 and r.id != floor.id]
    assert any(0.65 < h < 0.85 for h in above)  # a desk, 0.7-0.8 m above the floor


def test_mug_in_the_camera_frame_is_flagged_with_the_table_normal():
    cloud = load_cloud(MUG)
    with pytest.raises(InputError, match="does not look z-up") as info:
        check_up_direction(cloud.points, optical=True)
    up = np.array([float(v) for v in str(info.value).split('--transform "')[1].split('"')[0].split()])
    assert _angle_deg(up, MUG_NORMAL) < 2.0 and up @ MUG_NORMAL < 0  # up = away from the table


def _table_room(side: float, rng: np.random.Generator) -> np.ndarray:
    """A floor of side x side m with a 0.6 x 0.4 m table top at 0.74 m on four legs, 5 mm noise."""
    floor = np.c_[
        rng.uniform(-side / 2, side / 2, (int(side * side * 4000), 2)), np.zeros(int(side * side * 4000))
    ]
    top = np.c_[rng.uniform([-0.3, -0.2], [0.3, 0.2], (1000, 2)), np.full(1000, 0.74)]
    floor = floor[~((np.abs(floor[:, 0]) < 0.3) & (np.abs(floor[:, 1]) < 0.2))]  # under the table: hidden
    pts = np.vstack([floor, top])
    return pts + rng.normal(0, 0.005, pts.shape)


def test_a_0_24_m2_table_is_kept_at_default_settings():
    pts = _table_room(2.5, np.random.default_rng(4))
    terrain = terrain_from_points(pts)
    tops = [r for r in terrain.segmentation.regions if abs(r.centroid[2] - 0.74) < 0.03]
    assert len(tops) == 1
    assert tops[0].area == pytest.approx(0.24, rel=0.25)
    assert _angle_deg(tops[0].normal, np.array([0.0, 0.0, 1.0])) < 1.0


def test_auto_resolution_keeps_seed_000_cells_for_rooms():
    rng = np.random.default_rng(5)
    scene = generate_scene(SceneSettings(size_class="medium", n_planes=2), rng)
    assert auto_resolution(scene.sample_cloud(rng)) == 0.05  # generated scenes: unchanged
    assert auto_resolution(load_cloud(MUG).points) == 0.02


def test_sideways_scene_is_flagged_with_its_true_up():
    rng = np.random.default_rng(6)
    scene = generate_scene(SceneSettings(size_class="small", n_planes=2), rng)
    pts = scene.sample_cloud(rng)[::4]
    check_up_direction(pts)  # z-up: accepted
    R = load_transform("1 0 0")[:3, :3]  # world x becomes up: the floor is a wall
    with pytest.raises(InputError, match="does not look z-up") as info:
        check_up_direction(pts @ R.T)
    up = np.array([float(v) for v in str(info.value).split('--transform "')[1].split('"')[0].split()])
    assert _angle_deg(up, R @ np.array([0.0, 0.0, 1.0])) < 2.0 and up @ R[:, 2] > 0
    planes = dominant_planes(pts)
    assert _angle_deg(planes[0].normal, np.array([0.0, 0.0, 1.0])) < 1.0  # the floor dominates


def test_sac_plane_test_flagged_then_segmented_with_the_suggested_up(capsys):
    cloud = CLOUDS / "sac_plane_test.pcd"  # PCL's RANSAC test plane, tilted in its frame, with outliers
    assert main(["segment", str(cloud)]) == 2
    err = capsys.readouterr().err
    up = err.split('--transform "')[1].split('"')[0]
    assert main(["segment", str(cloud), "--transform", up, "--json"]) == 0
    import json

    (region,) = json.loads(capsys.readouterr().out)["regions"]
    assert region["tilt_deg"] < 3.0
    # the region's plane holds most of the raw points (a check on the data, not on the segmentation)
    pts = load_cloud(cloud).transformed(load_transform(up)).points
    n, d = np.array(region["normal"]), region["d"]
    assert np.mean(np.abs(pts @ n + d) < 0.03) > 0.5
