"""The platform execution oracle (baseplace_experiments/platform_execution.py) against ground truth.

Hand-built scenes with exact geometry: the footprint of a drawn pose across a platform's edge
(known from the footprint radius and the edge's distance) fails ``off_region``; a grasp whose
hand lies inside a platform block (known from the block's extent) has no collision-free IK
solution, while the same grasp over a lower block has one, and that solution touches the higher
block in a direct coal query.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.sim.scenes import Plane, Scene, SceneObject, SceneSettings
from baseplace_experiments.execution import ExecutionSettings
from baseplace_experiments.platform_execution import (
    PlatformOracle,
    drawn_on_plane,
    seated,
    true_scene_shapes,
)
from baseplace_experiments.table_grid import RobotShapes

FLOOR = Plane(0, "floor", (0.0, 0.0), (8.0, 8.0), 0.0, 0.0, 0.0, 0.0)
RAISED = Plane(2, "platform", (-2.5, 0.0), (1.6, 1.6), 0.0, 0.0, 0.1, 0.25)  # tilted about x, 0.25 m up
OBJECT = SceneObject("cylinder", (2.5, 2.5, 0.1), 0.0, (0.06, 0.06, 0.2))  # far away, on the floor
GRASP = pose_from_xyz_rpy([0.75, -0.15, 0.85, 0.0, 0.0, 0.0])  # side grasp in front of a base at the origin


def _scene(block_top: float) -> Scene:
    """The floor, a block 0.7-1.3 m in front of the origin with a level top, the raised platform."""
    block = Plane(1, "platform", (1.0, 0.0), (0.6, 1.2), 0.0, 0.0, 0.0, block_top)
    return Scene(SceneSettings(extent=(8.0, 8.0), with_box=False), (FLOOR, block, RAISED), None, (OBJECT,))


@pytest.fixture(scope="module")
def shapes(tiago):
    return RobotShapes(tiago)


def test_drawn_poses_stay_on_the_plane_and_seat_on_the_true_surface():
    T = plane_base_poses(-2.5, 0.0, 0.3, RAISED.normal, RAISED.d)[0]
    offsets = np.array([[0.05, -0.02, 0.03], [-0.03, 0.04, -0.02]])
    for D in drawn_on_plane(T, offsets):
        # on the plane z = a x + b y + c, z axis its normal, moved 5.4 / 5 cm
        assert D[2, 3] == pytest.approx(RAISED.z(D[None, :2, 3])[0], abs=1e-9)
        np.testing.assert_allclose(D[:3, 2], RAISED.normal, atol=1e-9)
        np.testing.assert_allclose(seated(D, RAISED), D, atol=1e-9)
    moved = drawn_on_plane(T, offsets)[:, :3, 3] - T[:3, 3]
    np.testing.assert_allclose(
        np.linalg.norm(moved, axis=1), np.hypot(offsets[:, 0], offsets[:, 1]), atol=1e-9
    )
    # a pose above the floor seats on it, level, heading kept
    S = seated(pose_from_xyz_rpy([1.0, 2.0, 0.4, 0.1, 0.0, 0.5]), FLOOR)
    assert S[2, 3] == 0.0 and math.atan2(S[1, 0], S[0, 0]) == pytest.approx(0.5)


def test_a_footprint_across_the_platform_edge_is_off_region(tiago, shapes):
    oracle = PlatformOracle(tiago, shapes, _scene(0.3), 0)
    r = tiago.spec.footprint_bounding_radius  # TIAGo: a 0.275 m circle
    edge = -2.5 + 0.8  # the raised platform's +x edge
    for x, inside in ((edge - r - 0.02, True), (edge - r + 0.02, False), (edge + 0.1, False)):
        T = plane_base_poses(x, 0.0, 0.0, RAISED.normal, RAISED.d)[0]
        assert (oracle.region(T).support == 2) is inside, x
    # on the floor: clear of the block's -x edge (x = 0.7) by more or less than the radius
    assert oracle.region(pose_from_xyz_rpy([0.7 - r - 0.02, 0, 0, 0, 0, 0])).support == 0
    assert oracle.region(pose_from_xyz_rpy([0.7 - r + 0.02, 0, 0, 0, 0, 0])).support is None
    # execute stops there, before IK or planning (no planner needed)
    T = plane_base_poses(edge - r + 0.02, 0.0, 0.0, RAISED.normal, RAISED.d)[0]
    assert oracle.execute(T, GRASP, None, np.random.default_rng(0))[0] == "off_region"  # type: ignore[arg-type]


def test_a_grasp_inside_a_platform_block_has_no_free_solution(tiago, shapes):
    settings = ExecutionSettings(ik_solutions=8)
    low = PlatformOracle(tiago, shapes, _scene(0.3), 0, settings).oracle(0)
    found = low.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0))
    assert found  # the grasp is reachable over the low block
    high_scene = _scene(1.0)  # the grasp point (0.75 + 0.15 ahead, 0.85 m up) lies inside the block
    assert high_scene.planes[1].contains(GRASP[None, :2, 3])[0] and GRASP[2, 3] < 1.0
    high = PlatformOracle(tiago, shapes, high_scene, 0, settings).oracle(0)
    assert high.grasp_configurations(np.eye(4), GRASP, np.random.default_rng(0)) == []
    obstacles, _ = true_scene_shapes(high_scene, 0, 0)
    for q in found:  # the low block's solutions, in a direct coal query on the high block
        assert shapes.touching(q, np.eye(4), obstacles) is not None
        assert not high.free(q, np.eye(4))


def test_the_base_resting_on_its_support_is_no_collision_but_sunk_into_it_is(tiago, shapes):
    oracle = PlatformOracle(tiago, shapes, _scene(0.3), 0)
    T = plane_base_poses(-2.5, 0.0, 0.0, RAISED.normal, RAISED.d)[0]
    on_raised = oracle.oracle(2)
    assert on_raised.free(on_raised.q_stowed, T)
    sunk = T.copy()
    sunk[2, 3] -= 0.1  # 10 cm into the platform
    assert not on_raised.free(on_raised.q_stowed, sunk)
