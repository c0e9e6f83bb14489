from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.sim.scenes import SceneSettings, generate_scene, truth_grid
from baseplace.terrain.graph import build_region_graph
from baseplace.terrain.heightmap import HeightMap
from baseplace.terrain.io import load_cloud, load_transform
from baseplace.terrain.pipeline import make_segmenter, terrain_from_points
from baseplace.terrain.polygons import footprint_inside, footprint_outline
from baseplace.terrain.voxels import VoxelMap
from baseplace_experiments.segmentation_eval import score_segmentation
from conftest import SHARED


@pytest.fixture(scope="module")
def scene_and_map():
    rng = np.random.default_rng([7, 1])
    scene = generate_scene(SceneSettings(size_class="medium", n_planes=2), rng)
    hmap = HeightMap.from_voxels(VoxelMap.from_points(scene.sample_cloud(rng), 0.025), 0.05)
    return scene, hmap


def test_voxels_and_height_map_against_known_points():
    pts = np.array([[0.01, 0.01, 0.31], [0.02, 0.03, 0.51], [0.07, 0.01, 0.10], [0.26, 0.26, 0.0]])
    vox = VoxelMap.from_points(pts, 0.025)
    np.testing.assert_array_equal(vox.keys, [[0, 0, 12], [0, 1, 20], [2, 0, 4], [10, 10, 0]])
    hm = HeightMap.from_voxels(vox, 0.05, sigma_cells=0)
    assert hm.origin == (0.0, 0.0) and hm.shape == (6, 6)
    assert hm.raw[0, 0] == pytest.approx(20.5 * 0.025)  # highest voxel centre of cell (0, 0)
    assert hm.raw[0, 1] == pytest.approx(4.5 * 0.025)
    assert np.isnan(hm.raw[1, 1]) and hm.known.sum() == 3
    with pytest.raises(InputError, match="no finite points"):
        VoxelMap.from_points(np.full((5, 3), np.nan))
    with pytest.raises(InputError, match="voxel resolution"):
        VoxelMap.from_points(pts, 0.0)
    with pytest.raises(InputError, match="height map resolution"):
        HeightMap.from_voxels(vox, 0.01)


def test_centres_at_some_cells_are_the_grid_centres_there_bit_for_bit(scene_and_map):
    _, hmap = scene_and_map
    X, Y = hmap.cell_centres()  # oracle: the (H, W) grids every caller read before
    rng = np.random.default_rng(4)
    rows, cols = rng.integers(0, hmap.shape[0], 500), rng.integers(0, hmap.shape[1], 500)
    x, y = hmap.centres_at(rows, cols)
    assert np.array_equal(x, X[rows, cols]) and np.array_equal(y, Y[rows, cols])
    # and by hand: cell (r, c) is centred half a cell past its corner
    assert x[0] == pytest.approx(hmap.origin[0] + (cols[0] + 0.5) * hmap.resolution, abs=1e-12)


@pytest.mark.parametrize(
    ("algorithm", "min_accuracy", "max_error_deg"), [("robust", 0.985, 0.5), ("baseline", 0.8, 15)]
)
def test_segmenters_against_ground_truth(scene_and_map, algorithm, min_accuracy, max_error_deg):
    scene, hmap = scene_and_map
    seg = make_segmenter(algorithm).segment(hmap)
    score = score_segmentation(scene, seg)
    assert score.accuracy >= min_accuracy
    assert score.missed_planes == 0
    assert max(score.normal_errors_deg) <= max_error_deg
    for region in seg.regions:  # Hessian form consistent with the stored centroid
        assert abs(region.normal @ region.centroid + region.d) < 0.05
        assert np.linalg.norm(region.normal) == pytest.approx(1.0) and region.normal[2] > 0


def test_robust_beats_baseline_and_finds_each_plane(scene_and_map):
    scene, hmap = scene_and_map
    robust = score_segmentation(scene, make_segmenter("robust").segment(hmap))
    baseline = score_segmentation(scene, make_segmenter("baseline").segment(hmap))
    assert robust.accuracy > baseline.accuracy
    assert robust.regions == len(scene.planes)


def test_polygons_and_footprint_inside(scene_and_map):
    scene, hmap = scene_and_map
    seg = make_segmenter("robust").segment(hmap)
    graph = build_region_graph(seg)
    plane = max(scene.planes[1:], key=lambda p: p.size[0] * p.size[1])
    truth, _ = truth_grid(scene, hmap.origin, hmap.resolution, hmap.shape)
    region_id = int(np.bincount(seg.labels[(truth == plane.id) & (seg.labels >= 0)]).argmax())
    polygon = graph.nodes[region_id]["polygon"]
    region = seg.regions[region_id]
    outline = footprint_outline(0.25, None)
    cx, cy = plane.center
    inside = plane_base_poses([cx], [cy], [0.3], region.normal, region.d)[0]
    assert footprint_inside(polygon, outline, inside, margin=0.05)
    corner = plane.polygon[0]  # a base centred on the plane's corner sticks out
    outside = plane_base_poses([corner[0]], [corner[1]], [0.3], region.normal, region.d)[0]
    assert not footprint_inside(polygon, outline, outside)
    # The polygon follows the true footprint to within a cell (oracle: the scene's rectangle).
    from shapely.geometry import Polygon

    true = Polygon(plane.polygon)
    assert polygon.difference(true.buffer(hmap.resolution * 1.5)).area < 0.02
    assert true.buffer(-hmap.resolution * 1.5).difference(polygon).area < 0.05


def test_region_graph_traversability(scene_and_map):
    scene, hmap = scene_and_map
    seg = make_segmenter("robust").segment(hmap)
    graph = build_region_graph(seg)
    truth, _ = truth_grid(scene, hmap.origin, hmap.resolution, hmap.shape)
    for plane in scene.planes[1:]:
        rid = int(np.bincount(seg.labels[(truth == plane.id) & (seg.labels >= 0)]).argmax())
        floor_edges = [e for _, other, e in graph.edges(rid, data=True) if other == 0]
        assert floor_edges, f"plane {plane.id} is not joined to the floor"
        traversable = [e for e in floor_edges if e["traversable"]]
        if plane.kind == "platform":  # raised 0.1-0.3 m everywhere: never drivable
            assert not traversable
        else:  # a ramp: drivable where its low edge meets the floor (z = 0 there, by construction)
            assert traversable
            for e in traversable:
                for p in (e["p_s"], e["p_e"]):
                    assert plane.z(np.asarray(p)[None])[0] < 0.06
            assert any(not e["traversable"] for e in floor_edges)  # the sides and high end drop off


def test_no_support_means_wrong_up_direction(scene_and_map):
    scene, _ = scene_and_map
    pts = scene.sample_cloud(np.random.default_rng(0))[::4]
    sideways = pts @ load_transform("1 0 0")[:3, :3].T  # world x becomes up: the floor is a wall
    with pytest.raises(InputError, match="up direction"):
        terrain_from_points(sideways)
    with pytest.raises(InputError, match="resolution"):
        terrain_from_points(pts, resolution=50.0)
    with pytest.raises(InputError, match="valid: baseline, robust"):
        terrain_from_points(pts, algorithm="ransac")


def test_real_table_scene_table_plane():
    # PCL's stereo tabletop; up vector from a RANSAC plane fit (independent of our segmentation).
    cloud = load_cloud(SHARED / "pointclouds" / "table_scene_mug_stereo_textured.pcd")
    cloud = cloud.transformed(load_transform("0.01 -0.845 -0.534"))
    terrain = terrain_from_points(cloud.points, resolution=0.02)
    table = max(terrain.segmentation.regions, key=lambda r: r.area)
    assert table.tilt < math.radians(5)
    assert 0.1 < table.area < 0.4  # the tabletop in view is about 0.6 x 0.4 m, less the mug
    assert table.centroid[2] == pytest.approx(-0.515, abs=0.03)


def test_real_office_floor():
    # Kinect office scene; up = the floor normal from a RANSAC fit: floor 1.466 m below the camera.
    cloud = load_cloud(SHARED / "pointclouds" / "office1.pcd").transformed(
        load_transform("-0.0361 -0.9991 -0.0217")
    )
    terrain = terrain_from_points(cloud.points)
    floor = min((r for r in terrain.segmentation.regions if r.area > 1.0), key=lambda r: r.centroid[2])
    assert floor.centroid[2] == pytest.approx(-1.466, abs=0.05)
    assert floor.tilt < math.radians(5)
