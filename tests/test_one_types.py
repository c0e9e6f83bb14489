"""One cloud type and one base-pose type across the library's functions (issue 16 item 6)."""

from __future__ import annotations

import math
import typing

import numpy as np
import pytest

from baseplace.geometry.poses import BasePose, pose_from_xyz_rpy
from baseplace.placement.surface_sampling import SurfaceSample
from baseplace.placement.verify import Placement
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.io import Cloud
from baseplace.terrain.pipeline import terrain_from_points
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.grasped_object import find_grasped_object


def test_a_cloud_goes_wherever_points_go():
    rng = np.random.default_rng(1)
    scene = generate_scene(SceneSettings(n_planes=1, extent=(4.0, 4.0)), rng)
    points = scene.sample_cloud(rng, sigma=0.0)
    cloud = Cloud(points, source="generated")
    assert np.asarray(cloud) is cloud.points and np.asarray(cloud, dtype=np.float32).dtype == np.float32
    assert np.asarray(cloud, copy=True) is not cloud.points
    a, b = terrain_from_points(points, resolution=0.05), terrain_from_points(cloud, resolution=0.05)
    assert np.array_equal(a.segmentation.labels, b.segmentation.labels)
    assert np.array_equal(VoxelMap.from_points(cloud).keys, VoxelMap.from_points(points).keys)
    box = scene.box
    assert box is not None and scene.objects
    obj = scene.objects[0]
    grasp = [obj.center[0], obj.center[1], obj.top - 0.02]
    by_array, by_cloud = find_grasped_object(points, grasp), find_grasped_object(cloud, grasp)
    assert by_array is not None and by_cloud is not None
    assert np.array_equal(by_array.points, by_cloud.points)


@pytest.mark.parametrize("yaw", [0.3, -2.9, math.pi])
def test_every_base_pose_converts_to_base_pose(yaw):
    """Oracle: the pose the 4x4 was built from; headings compared on the circle."""
    T = pose_from_xyz_rpy([1.5, -0.25, 0.12, 0.0, 0.0, yaw])
    placed = Placement(T, 0, 0.5, [], ()).pose
    sampled = BasePose.from_xyyaw(1.5, -0.25, yaw)
    assert typing.get_type_hints(SurfaceSample)["pose"] is BasePose  # a surface sample holds one, is none
    for pose in (placed, sampled):
        assert isinstance(pose, BasePose)
        assert (pose.x, pose.y) == pytest.approx((1.5, -0.25))
        assert math.cos(pose.yaw - yaw) == pytest.approx(1.0)
    assert np.allclose(placed.matrix()[:2], T[:2]) and np.allclose(sampled.matrix()[:2], T[:2])
