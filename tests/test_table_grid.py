from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import BasePose
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.viz.table_grid import plot_table_grid
from baseplace_experiments.table_grid import (
    CHOSEN,
    DEV_CHOICES,
    METHODS,
    PAPER_SUCCESS_RATE,
    PAPER_TABLE1,
    SEEDS,
    GraspOracle,
    RobotShapes,
    TableGridSettings,
    object_cloud,
    radial_settings,
    run_table_grid,
    table_cloud,
    table_occupancy,
    true_bottle,
    true_table,
    without_object,
)

SETTINGS = TableGridSettings()


def test_paper_table_matches_the_seeds_rates():
    assert set(PAPER_TABLE1) == {(i, j) for i in range(3) for j in range(4)}
    for column in ("proposed", "baseline"):
        assert all(sum(row[column]) == 5 for row in PAPER_TABLE1.values())
        wins = sum(row[column][0] for row in PAPER_TABLE1.values())
        assert round(100 * wins / 60, 1) == PAPER_SUCCESS_RATE[column]


def test_grid_lies_on_the_table():
    x0, x1, y0, y1 = SETTINGS.table_bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((0.8, 1.8))
    c00, c23 = SETTINGS.cell_centre(0, 0), SETTINGS.cell_centre(2, 3)
    assert c00[0] - 0.1 == pytest.approx(x0 + 0.1)  # 0.1 m margins across the width
    assert c23[0] + 0.1 == pytest.approx(x1 - 0.1)
    assert c00[1] - 0.1 == pytest.approx(y0)  # row 0 starts at the short edge
    assert c23[1] + 0.1 == pytest.approx(y0 + 0.8)
    assert c00[2] == pytest.approx(0.74 + 0.1)
    with pytest.raises(ValueError, match="off the 3 x 4 grid"):
        SETTINGS.cell_centre(3, 0)


def test_occupancy_and_clouds():
    grid = table_occupancy(SETTINGS)
    x0, x1, y0, y1 = SETTINGS.table_bounds
    assert (
        grid.value_at(
            [[(x0 + x1) / 2, (y0 + y1) / 2], [x0 + 0.01, y0 + 0.01], [x1 - 0.01, y1 - 0.01]]
        ).tolist()
        == [100] * 3
    )
    assert grid.value_at([[x0 - 0.03, y0], [1.0, 1.0], [x1 + 0.03, y1 + 0.03]]).tolist() == [0] * 3
    assert grid.value_at([[0.01, 3.0], [5.99, 3.0], [3.0, 0.01], [3.0, 5.99]]).tolist() == [100] * 4
    table = table_cloud(SETTINGS)
    assert table[:, 0].min() >= x0 - 1e-9 and table[:, 0].max() <= x1 + 1e-9
    assert table[:, 2].max() == pytest.approx(0.74) and table[:, 2].min() == pytest.approx(0.0)
    p = SETTINGS.cell_centre(1, 2)
    bottle = object_cloud(p, SETTINGS)
    assert np.hypot(bottle[:, 0] - p[0], bottle[:, 1] - p[1]).max() <= 0.035 + 1e-9
    assert bottle[:, 2].min() == pytest.approx(0.74) and bottle[:, 2].max() == pytest.approx(0.94)
    table_voxels = VoxelMap.from_points(table, 0.025).keys
    for estimate in (p, p + np.array([0.025, -0.01, 0.0])):  # also around an estimate 2.7 cm off
        kept = without_object(np.concatenate([table, bottle]), estimate, SETTINGS)
        assert len(kept) == len(table) + (bottle[:, 2] == bottle[:, 2].min()).sum()  # the bottom ring stays
        assert np.array_equal(VoxelMap.from_points(kept, 0.025).keys, table_voxels)


@pytest.fixture(scope="module")
def robot_shapes(tiago):
    return RobotShapes(tiago)


@pytest.fixture(scope="module")
def oracle_setup(robot_shapes):
    p = SETTINGS.cell_centre(0, 1)
    return GraspOracle(robot_shapes, p, SETTINGS), p


def test_true_shapes_match_the_cloud():
    """The oracle's boxes and cylinder hold the synthetic cloud's points (the methods' view of the same scene)."""
    table, p = table_cloud(SETTINGS), SETTINGS.cell_centre(2, 3)
    sphere = __import__("coal").Sphere(0.002)
    request = __import__("coal").CollisionRequest()

    def inside(shapes, pts):
        hit = []
        for x in pts:
            T = __import__("coal").Transform3s(np.eye(3), x)
            hit.append(any(__import__("coal").collide(sphere, T, s.geometry, s.transform(), request,
                                                      __import__("coal").CollisionResult()) for s in shapes))  # fmt: skip
        return np.array(hit)

    rng = np.random.default_rng(0)
    assert inside(true_table(SETTINGS), table[rng.choice(len(table), 300)]).all()
    bottle = object_cloud(p, SETTINGS)
    assert inside([true_bottle(p, SETTINGS)], bottle[rng.choice(len(bottle), 100)]).all()
    assert not inside(true_table(SETTINGS), np.array([[1.0, 1.0, 0.5], [3.0, 3.0, 0.80]])).any()


def test_only_the_hand_may_touch_the_grasped_object(tiago, robot_shapes):
    """A cylinder around the gripper is allowed as the grasped object, not as an obstacle; around the elbow, never."""
    arm, model, data = tiago.arm(), tiago.model, tiago.model.createData()
    q = (arm.lower + arm.upper) / 2
    base = np.eye(4)
    pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, tiago.q_reference))
    root_base = data.oMf[model.getFrameId(tiago.spec.base_frame)].homogeneous
    assert robot_shapes.touching(q, base, []) is None  # the mid-range posture is free of self-collision
    T_base_tcp = np.linalg.inv(root_base) @ data.oMf[model.getFrameId(arm.tcp_frame)].homogeneous
    # where the hand grasps: the standoff ahead of the TCP along its approach axis
    around_hand = true_bottle(T_base_tcp[:3, 3] + SETTINGS.standoff * T_base_tcp[:3, 0], SETTINGS)
    assert robot_shapes.touching(q, base, [], grasped=around_hand) is None
    assert robot_shapes.touching(q, base, [around_hand]) is not None
    elbow = (np.linalg.inv(root_base) @ data.oMi[model.getJointId(arm.joint_names[3])].homogeneous)[:3, 3]
    hit = robot_shapes.touching(q, base, [], grasped=true_bottle(elbow, SETTINGS))
    assert hit is not None and hit.endswith("bottle")


def test_oracle_accepts_an_fk_checked_grasp(tiago, oracle_setup):
    oracle, p = oracle_setup
    arm = tiago.arm()
    # A side grasp straight ahead (grasp 0: approach +x) 0.6 m in front of the base, at the bottle's height.
    T_base_tcp = np.eye(4)
    T_base_tcp[:3, 3] = (0.6, -0.1, p[2])
    ik = DampedLeastSquaresIK(arm)
    rng = np.random.default_rng(1)
    model, data = tiago.model, tiago.model.createData()
    base = BasePose(p[0] - SETTINGS.standoff - 0.6, p[1] + 0.1, 0.0)
    assert np.allclose(base.matrix() @ T_base_tcp, oracle.grasps[0])
    for _ in range(20):  # a collision-free solution, its TCP checked with pinocchio's FK
        q = ik.solve(T_base_tcp, rng)
        assert q is not None
        pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, tiago.q_reference))
        T_fk = (
            data.oMf[model.getFrameId(arm.base_frame)].inverse() * data.oMf[model.getFrameId(arm.tcp_frame)]
        ).homogeneous
        assert np.allclose(T_fk, T_base_tcp, atol=1e-3)
        if oracle.touching(q, base.matrix()) is None:
            break
    else:
        pytest.fail("no collision-free IK solution for the test's grasp")
    assert oracle.grasp(base, np.random.default_rng(0)) >= 0


def test_oracle_rejects_inside_the_table_and_far_away(oracle_setup):
    oracle, p = oracle_setup
    rng = np.random.default_rng(0)
    assert oracle.grasp(BasePose(p[0] + 0.1, p[1] - 0.3, math.pi / 2), rng) == -1  # torso through the top
    assert oracle.grasp(BasePose(0.8, 0.8, math.atan2(p[1] - 0.8, p[0] - 0.8)), rng) == -1  # 2.6 m away


def test_smoke_run_and_plot(tiago, tiago_map, tmp_path):
    steps: list[int] = []
    cells = [(0, 0), (1, 3)]
    result = run_table_grid(tiago, tiago_map, trials=1, seed=0, progress=steps.append, cells=cells)
    assert steps == [1, 1]
    json.dumps(result)
    assert [row["cell"] for row in result["cells"]] == [list(c) for c in cells]
    for method in METHODS:
        grid = result["grids"][method]
        assert len(grid) == 4 and all(len(row) == 3 for row in grid)
        assert sum(v is not None for row in grid for v in row) == 2
        t = result["totals"][method]
        assert t["success"] + t["failure"] == 2
        assert 0 <= t["missed"] <= t["failure"]
        assert [row["table1"][method][0] for row in result["cells"]] == [grid[j][i] for i, j in cells]
    for row in result["cells"]:
        trial = row["trials"][0]
        assert set(trial["methods"]) == set(METHODS)
        assert isinstance(trial["feasible"], bool)
        for entry in trial["methods"].values():
            assert entry["success"] == (entry["reason"] == "ok")
            if entry["success"]:
                assert trial["feasible"]  # a working placement is a placement that works
        assert np.hypot(*np.subtract(trial["true"][:2], row["centre"][:2])) <= math.sqrt(2) * 0.05 + 1e-9
    assert result["cells"][0]["trials"][0]["methods"]["baseline"]["success"]  # the cell before it
    assert result["radial_settings"]["surface_margin"] == CHOSEN["surface_margin"]
    assert result["settings"]["method_top_below"] == CHOSEN["method_top_below"]
    assert all(CHOSEN[k] in DEV_CHOICES[k] for k in CHOSEN) and not set(SEEDS.dev) & set(SEEDS.held_out)
    assert result["radial_settings"]["d_max"] == pytest.approx(tiago_map.horizontal_reach)
    assert radial_settings(tiago, tiago_map, SETTINGS, 0.02).surface_margin == 0.02
    png = tmp_path / "grid.png"
    plot_table_grid(result, png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["grid.png"]
