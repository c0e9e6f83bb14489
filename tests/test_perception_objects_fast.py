"""The compiled point-in-hull test of the support planes gives what the numpy one it replaced gave.

The numpy test (kept here as the oracle) built an (N, K, 2) array for the frame's 300 000 points
against each hull's K edges: about half of the objects step's time (bench/bench_point.py).
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
def test_the_dev_frames_give_the_same_objects_as_with_the_numpy_test(seed, monkeypatch):
    scene = generate_pointing_scene(seed)  # the pointing experiment's dev seeds
    T = scene.T_world_camera
    points = RgbdFrame(scene.rgb, scene.depth, scene.intrinsics).points_camera() @ T[:3, :3].T + T[:3, 3]
    hand = scene.landmarks[:, :2] * [scene.depth.shape[1], scene.depth.shape[0]] - 0.5
    fast = detect_objects(points, None, hand)
    monkeypatch.setattr(objects.SupportPlane, "holds", holds_numpy)
    slow = detect_objects(points, None, hand)
    assert len(fast.objects) == len(slow.objects) > 0
    for a, b in zip(fast.objects, slow.objects, strict=True):
        assert np.array_equal(a.box_world, b.box_world) and np.array_equal(a.image_box, b.image_box)
        assert a.n_points == b.n_points and a.support_height == b.support_height
    assert np.array_equal(fast.hand, slow.hand)
