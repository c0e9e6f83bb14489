from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import BasePose
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.sim.table_grid import (
    METHODS,
    PAPER_SUCCESS_RATE,
    PAPER_TABLE1,
    GraspOracle,
    TableGridSettings,
    object_cloud,
    radial_settings,
    run_table_grid,
    table_cloud,
    table_occupancy,
    without_object,
)
from baseplace.terrain.voxels import VoxelMap
from baseplace.viz.table_grid import plot_table_grid

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
def oracle_setup(tiago):
    p = SETTINGS.cell_centre(0, 1)
    clean = np.concatenate([table_cloud(SETTINGS), object_cloud(p, SETTINGS)])
    voxels = VoxelMap.from_points(without_object(clean, p, SETTINGS), SETTINGS.voxel_size)
    return GraspOracle(tiago, None, voxels, p, SETTINGS), p


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
        if not oracle.environment.colliding_arm(arm, q, base.matrix()):
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
    assert result["radial_settings"]["surface_margin"] == 0.04
    assert result["radial_settings"]["d_max"] == pytest.approx(tiago_map.horizontal_reach)
    assert radial_settings(tiago, tiago_map, SETTINGS, tuned=False).surface_margin == 0.02
    png = tmp_path / "grid.png"
    plot_table_grid(result, png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["grid.png"]
