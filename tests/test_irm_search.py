"""The IRM candidate search finds the placements that exist (issue 25, the table-grid experiment's dev finding).

On the experiment's dev scenes the side grasps' fingers came closer to the table than the
clearance: clear of it at zero margin, so the hand filter kept them, but refused by the verifier
(``hand_*_link touched support``) from every base pose, and they took most of the 300 checks. The
scene here is that, made small: a table top at sensor resolution (5 mm cells, the clearance
applies), side grasps whose fingers lie 4-9 mm above it, top-down grasps well clear.

Oracles, independent of the search: coal on the true table (a box) for the hand's and the whole
robot's geometry posed by pinocchio, and pinocchio FK of the returned joints for the grasp.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.placement.irm_candidates import IrmSettings, grasp_poses, hand_feasible, irm_candidates
from baseplace.robots.collision import load_collision_model
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment, HandFilter
from conftest import tcp_by_pinocchio

TOP = 0.72  # the true table top [m]
HALF = 0.4  # the table top is 0.8 m square, centred on the origin
CLEARANCE = 0.01
TABLE = coal.Box(2 * HALF, 2 * HALF, 0.004)
T_TABLE = coal.Transform3s(np.eye(3), np.array([0.0, 0.0, TOP - 0.002]))


@pytest.fixture(scope="module")
def scene(tiago):
    """(environment, grasps (16, 4, 4), object position): 8 side grasps skimming the table, 8 top-down."""
    g = np.arange(-HALF, HALF, 0.004)
    points = np.stack(np.meshgrid(g, g, [TOP - 0.002]), -1).reshape(-1, 3)  # the table top as seen
    env = Environment(tiago, {"support": VoxelMap.from_points(points, 0.005)}, clearance=CLEARANCE)
    p_o = np.array([0.0, 0.3, TOP + 0.09])
    side = grasp_poses(p_o, n=8, standoff=0.15)
    top_down = grasp_poses(p_o, n=8, top_down=True, standoff=0.15, top_offset=0.12)[8:]
    return env, np.concatenate([side, top_down]), p_o


def _hand_gap(robot, T_world_tcp) -> float:
    """Oracle: the hand's distance [m] to the true table, coal on the URDF's hand geometry."""
    gaps = []
    for geometry, T_tcp_geom in HandFilter(robot).parts:
        T = T_world_tcp @ T_tcp_geom
        result = coal.DistanceResult()
        gaps.append(coal.distance(geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), TABLE, T_TABLE,
                                  coal.DistanceRequest(), result))  # fmt: skip
    return min(gaps)


def test_the_hand_filter_keeps_no_grasp_whose_fingers_are_within_the_clearance(tiago, scene):
    env, grasps, _ = scene
    gaps = np.array([_hand_gap(tiago, g) for g in grasps])
    assert np.all((gaps[:8] > 0) & (gaps[:8] < CLEARANCE - 0.001))  # clear, but closer than the clearance
    assert np.all(gaps[8:] > 5 * CLEARANCE)
    ok = hand_feasible(tiago, None, grasps, env)
    assert ok.tolist() == [False] * 8 + [True] * 8, ok.tolist()


def test_the_search_finds_the_top_down_placements_behind_the_skimming_side_grasps(tiago, tiago_map, scene):
    env, grasps, p_o = scene
    settings = IrmSettings(count=2)
    found = irm_candidates(tiago, tiago_map, p_o, grasps, env, None, settings, np.random.default_rng(0))
    assert len(found) == settings.count, f"found {len(found)} placements in {settings.max_checks} checks"
    arm = tiago.arm()
    geom = load_collision_model(tiago)
    data, gdata = tiago.model.createData(), pin.GeometryData(geom)
    base_id = tiago.model.getFrameId(arm.base_frame)
    for c in found:
        assert c.grasp is not None and c.grasp >= 8  # only top-down grasps can pass
        q = c.joints[0]
        assert np.all(q >= arm.lower - 1e-9) and np.all(q <= arm.upper + 1e-9)
        T_world_tcp = c.pose.matrix() @ tcp_by_pinocchio(tiago, arm, q)
        G = grasps[c.grasp]
        assert np.linalg.norm(T_world_tcp[:3, 3] - G[:3, 3]) < 1e-4
        assert np.linalg.norm(pin.log3(G[:3, :3].T @ T_world_tcp[:3, :3])) < 1e-3
        q_full = arm.to_pinocchio(q, tiago.q_reference)
        pin.framesForwardKinematics(tiago.model, data, q_full)
        pin.updateGeometryPlacements(tiago.model, data, geom, gdata, q_full)
        T_world_root = c.pose.matrix() @ data.oMf[base_id].inverse().homogeneous
        for k, obj in enumerate(geom.geometryObjects):
            T = T_world_root @ gdata.oMg[k].homogeneous
            result = coal.CollisionResult()
            touches = coal.collide(obj.geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), TABLE, T_TABLE,
                                   coal.CollisionRequest(), result)  # fmt: skip
            assert not touches, f"{obj.name} touches the true table at base {c.pose}"


def test_the_search_order_visits_every_position_before_a_second_heading():
    """Oracle: a plain loop over positions, round by round, on random map values."""
    from baseplace.placement.irm_candidates import search_order

    rng = np.random.default_rng(7)
    n_yaw, positions, grasps = 4, 6, 3
    values = rng.uniform(0.0, 1.0, (grasps, positions * n_yaw)) * (
        rng.uniform(size=(grasps, positions * n_yaw)) > 0.3
    )
    order = [tuple(map(int, row)) for row in search_order(values, n_yaw)]
    pairs = {p: sorted(((-values[k, i], k, i) for k, i in zip(*np.nonzero(values > 0), strict=True) if i // n_yaw == p))
             for p in range(positions)}  # fmt: skip
    expected = []
    for turn in range(grasps * n_yaw):
        row = sorted(pairs[p][turn] for p in range(positions) if turn < len(pairs[p]))
        expected += [(k, i) for _, k, i in row]
    assert order == expected
