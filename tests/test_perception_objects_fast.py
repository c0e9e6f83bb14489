"""The objects step's faster parts give what the code they replaced gave (kept here as the oracles).

The numpy point-in-hull test built an (N, K, 2) array for the frame's 300 000 points against each
hull's K edges (about half of the objects step's time, bench/bench_point.py); the clustering
labelled a dense grid over the object points' bounding box with ``ndimage.label``.
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.perception import objects
from baseplace.perception.objects import SupportPlane, detect_objects
from baseplace.perception.rgbd import RgbdFrame
from baseplace.sim.pointing_scenes import generate_pointing_scene


def holds_numpy(plane: SupportPlane, xy: np.ndarray) -> np.ndarray:
    """The landed ``SupportPlane.holds``: inside or on every counter-clockwise edge (cross >= -1e-9)."""
    h = plane.hull
    edges = np.roll(h, -1, axis=0) - h
    rel = xy[:, None, :] - h[None]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    return np.asarray(np.all(cross >= -1e-9, axis=1))


def components_dense(keys: np.ndarray) -> tuple[np.ndarray, int]:
    """The landed clustering: ``ndimage.label`` (26-neighbours) on the dense grid of the voxels' box."""
    from scipy import ndimage

    lo = keys.min(axis=0)
    grid = np.zeros(tuple(int(v) for v in keys.max(axis=0) - lo + 1), dtype=bool)
    grid[tuple((keys - lo).T)] = True
    labels, n = ndimage.label(grid, structure=np.ones((3, 3, 3), dtype=bool))
    return labels[tuple((keys - lo).T)] - 1, n


def test_voxel_components_number_the_clusters_as_ndimage_label():
    rng = np.random.default_rng(1)
    blobs = [rng.integers(0, 6, (200, 3)) + rng.integers(-40, 40, 3) for _ in range(30)]
    chain = np.c_[np.arange(50), np.arange(50), np.zeros(50, dtype=int)]  # diagonal neighbours only
    keys = np.concatenate([*blobs, chain, rng.integers(-60, 60, (300, 3)), [[-1000, 5, 7]]]).astype(np.int64)
    keys = keys[rng.permutation(len(keys))]
    got, want = objects._voxel_components(keys), components_dense(keys)
    assert got[1] == want[1] and np.array_equal(got[0], want[0])
    assert 30 < want[1] < len(keys)


def test_holds_matches_the_numpy_test_on_random_points_edges_corners_and_nan():
    rng = np.random.default_rng(0)
    angles = np.sort(rng.uniform(0, 2 * np.pi, 40))
    hull = np.c_[np.cos(angles), 0.5 * np.sin(angles)] + [2.0, -1.0]
    plane = SupportPlane(np.array([0.0, 0.0, 1.0]), -0.7, hull)
    mid = (hull + np.roll(hull, -1, axis=0)) / 2
    xy = np.concatenate([rng.uniform([0.5, -2], [3.5, 0], (20000, 2)), hull, mid,
                         [[np.nan, -1.0], [2.0, np.nan], [np.inf, 0.0]]])  # fmt: skip
    got, want = plane.holds(xy), holds_numpy(plane, xy)
    assert got.dtype == bool and np.array_equal(got, want)
    assert 0 < want.sum() < len(xy) and not got[-3:].any()


@pytest.mark.parametrize("seed", [0, 1])
def test_the_dev_frames_give_the_same_objects_as_with_the_landed_code(seed, monkeypatch):
    scene = generate_pointing_scene(seed)  # the pointing experiment's dev seeds
    T = scene.T_world_camera
    points = RgbdFrame(scene.rgb, scene.depth, scene.intrinsics).points_camera() @ T[:3, :3].T + T[:3, 3]
    hand = scene.landmarks[:, :2] * [scene.depth.shape[1], scene.depth.shape[0]] - 0.5
    fast = detect_objects(points, None, hand)
    monkeypatch.setattr(objects.SupportPlane, "holds", holds_numpy)
    monkeypatch.setattr(objects, "_voxel_components", components_dense)
    slow = detect_objects(points, None, hand)
    assert len(fast.objects) == len(slow.objects) > 0
    for a, b in zip(fast.objects, slow.objects, strict=True):
        assert np.array_equal(a.box_world, b.box_world) and np.array_equal(a.image_box, b.image_box)
        assert a.n_points == b.n_points and a.support_height == b.support_height
    assert np.array_equal(fast.hand, slow.hand)
