"""Queries that share one scene's cache (issue 18: per-query cost).

Oracles: pinocchio FK of the returned joints (the placement reaches the target), and the
geometry of two bottles 3 cm apart: a grasp of one whose hand passes through the other must fail
whichever object an earlier query in the same cache held.
"""

from __future__ import annotations

import math

import numpy as np

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.pipeline import PlaceSettings, place
from baseplace.placement.scene_cache import SceneCache
from test_grasped_object import BOTTOM, THROUGH_B, A, B, bottle, cloud, tray_scene
from test_placement import pinocchio_tcp

# B grasped from A's side: the mirror of THROUGH_B
THROUGH_A = pose_from_xyz_rpy([0.05 - 0.151, 0.0, 0.70, 0.0, 0.0, 0.0])


def test_repeated_queries_reuse_the_scene_and_still_reach_the_target(tiago, tiago_map):
    points = cloud(tray_scene(A))
    cache = SceneCache(points)
    settings = PlaceSettings(tries=60)
    first = place(tiago, tiago_map, points, THROUGH_B, settings, np.random.default_rng(0), grasped="auto",
                  cache=cache)  # fmt: skip
    assert first.placements, dict(first.failures)
    built = cache.misses
    for seed in (1, 2):
        again = place(tiago, tiago_map, points, THROUGH_B, settings, np.random.default_rng(seed),
                      grasped="auto", cache=cache)  # fmt: skip
        assert cache.misses == built  # nothing rebuilt: segmentation, obstacles, environment kept
        assert again.terrain is first.terrain
        assert again.timings_ms["collision_setup"] < first.timings_ms["collision_setup"]
        for p in again.placements:  # oracle: pinocchio FK of the returned joints reaches the grasp
            arm = tiago.arm(tiago_map.info.arm)
            T = pinocchio_tcp(tiago, arm, p.joints[0], p.T_world_base)
            assert np.allclose(T[:3, 3], THROUGH_B[:3, 3], atol=0.01)


def test_each_grasped_object_gets_its_own_allowed_contact(tiago, tiago_map):
    # two bottles 24 cm apart, each grasped from above with the fingers around its top: the hand
    # touches the held bottle (allowed) and would collide with it were the other one's contact kept
    left, right = bottle(-0.12), bottle(0.12)
    points = cloud(tray_scene(left, right))
    cache = SceneCache(points)
    top = BOTTOM + 0.25

    def grasp(x: float) -> np.ndarray:
        return pose_from_xyz_rpy([x, 0.0, top - 0.04 + 0.151, 0.0, math.pi / 2, 0.0])

    for held in (left, right, left):
        res = place(tiago, tiago_map, points, grasp(held.center[0]), PlaceSettings(tries=40),
                    np.random.default_rng(0), grasped="auto", cache=cache)  # fmt: skip
        assert res.grasped is not None and math.isclose(res.grasped.center[0], held.center[0], abs_tol=0.02)
        assert res.placements, (held.center, dict(res.failures), res.contacts)
        for p in res.placements:
            T = pinocchio_tcp(tiago, tiago.arm(tiago_map.info.arm), p.joints[0], p.T_world_base)
            assert np.allclose(T[:3, 3], grasp(held.center[0])[:3, 3], atol=0.01)
    # and a grasp through the neighbour still fails in a cache that held the neighbour before
    points = cloud(tray_scene(A, B))
    cache = SceneCache(points)
    for target in (THROUGH_A, THROUGH_B):  # B held (A an obstacle), then A (B an obstacle again)
        res = place(tiago, tiago_map, points, target, PlaceSettings(tries=40), np.random.default_rng(0),
                    grasped="auto", cache=cache)  # fmt: skip
        assert not res.placements and any(
            link.startswith("hand") and what == "obstacle" for link, what in res.contacts
        )


def test_a_robot_and_its_collision_model_are_freed_with_it():
    # a long-running service builds robots; their self-collision checkers must not outlive them
    import gc
    import weakref

    from baseplace.robots.model import Robot
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment

    robot = Robot("tiago")
    env = Environment(robot, VoxelMap.from_points(np.zeros((1, 3))))
    assert env.colliding(robot.q_reference, np.eye(4)) in (True, False)
    alive = weakref.ref(robot)
    del robot, env
    gc.collect()
    assert alive() is None


def test_points_near_are_the_brute_force_window_in_the_clouds_order():
    # oracle: every point tested, in the cloud sorted by x (stable), as points_near gave them before the grid
    rng = np.random.default_rng(5)
    points = np.r_[
        rng.uniform(-5, 5, (20_000, 3)), np.round(rng.uniform(-1, 1, (2_000, 3)), 1)
    ]  # ties, edges
    cache = SceneCache(points)
    by_x = points[np.argsort(points[:, 0], kind="stable")]
    for xy, half in [((0.0, 0.0), 0.4), ((4.9, -4.9), 0.5), ((0.3, 0.5), 0.25), ((-7.0, 0.0), 1.0),
                     ((0.0, 9.0), 0.5), ((1.0, 1.0), 0.0), ((0.0, 0.0), 20.0)]:  # fmt: skip
        truth = by_x[(np.abs(by_x[:, 0] - xy[0]) <= half) & (np.abs(by_x[:, 1] - xy[1]) <= half)]
        assert np.array_equal(cache.points_near(xy, half), truth), (xy, half)


def test_the_grasped_object_found_in_the_window_is_the_one_found_in_the_whole_cloud():
    from baseplace.placement.pipeline import _grasped_object
    from baseplace.robots.model import Robot
    from baseplace.world.grasped_object import find_grasped_object

    tiago = Robot("tiago")
    points = cloud(tray_scene(A, B))
    cache = SceneCache(points)
    for T in (THROUGH_A, THROUGH_B):
        windowed, _ = _grasped_object(tiago, "arm", points, T[None], "auto", cache)
        whole, _ = _grasped_object(tiago, "arm", points, T[None], "auto", None)
        assert windowed is not None and whole is not None
        # the same points (the window keeps the cloud's x order, the whole cloud its own)
        assert np.array_equal(np.unique(windowed.points, axis=0), np.unique(whole.points, axis=0))
        assert len(windowed.points) == len(whole.points)
    assert find_grasped_object(points, THROUGH_A[:3, 3] + [0.0, 0.0, 2.0]) is None
