from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, invert_transforms
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.reachability.build import CHUNK, BuildSettings, MapAccumulator, build_map
from baseplace.reachability.rmap import ArmCombination, inverse_reachability
from test_kinematics import pinocchio_fk


def test_every_build_sample_is_in_the_map(tiago, tiago_map):
    # Oracle: pinocchio FK of the very samples the build drew (recall on training poses is exact).
    acc = MapAccumulator(tiago, None, BuildSettings(samples=2_000_000, seed=3))
    Q = acc.chunk_samples(1)[:3000]
    T = pinocchio_fk(tiago, tiago.arm(), Q)
    assert np.all(tiago_map.reachability(T) > 0)
    assert int(tiago_map.counts.sum()) == 2_000_000
    assert 0 < tiago_map.index.min() and tiago_map.index.max() == 1.0


def test_poses_beyond_reach_are_zero(tiago_map):
    T = np.repeat(np.eye(4)[None], 3, axis=0)
    T[:, :3, 3] = [[2.5, 0, 1], [0, 0, -1.0], [0, 0, 4]]
    np.testing.assert_array_equal(tiago_map.reachability(T), 0.0)


def test_same_seed_same_map_other_seed_differs(planar3):
    s = BuildSettings(samples=CHUNK + 5000, seed=9, voxel_size=0.05)
    a, b = build_map(planar3, None, s), build_map(planar3, None, s)
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.counts, b.counts)
    c = build_map(planar3, None, BuildSettings(samples=CHUNK + 5000, seed=10))
    assert not (len(a.cells) == len(c.cells) and np.array_equal(a.counts, c.counts))


def test_inverse_query_equals_forward_lookup(tiago, tiago_map, rng):
    arm = tiago.arm()
    trained = MapAccumulator(tiago, None, BuildSettings(samples=2_000_000, seed=3)).chunk_samples(0)[:200]
    T_base_tcp = pinocchio_fk(tiago, arm, trained)  # poses the map holds
    bases = BasePose.batch_matrix(np.c_[rng.uniform(-2, 2, (200, 2)), rng.uniform(-np.pi, np.pi, 200)])
    for T_wb, T_bt in zip(bases[:20], T_base_tcp[:20], strict=True):
        T_world_target = T_wb @ T_bt  # the base at T_wb reaches this world target
        value = tiago_map.inverse(T_world_target, T_wb[None])
        assert value[0] == tiago_map.reachability(T_bt[None])[0] > 0
    # batch: one target, many bases, against explicit inversion
    target = bases[0] @ T_base_tcp[0]
    expected = tiago_map.reachability(invert_transforms(bases) @ target)
    np.testing.assert_array_equal(tiago_map.inverse(target, bases), expected)


def test_plane_constrained_bases_on_a_ramp(tiago, tiago_map, rng):
    # A base standing on a 10 degree ramp reaches what its own FK says, wherever the ramp is.
    arm = tiago.arm()
    n = np.array([np.sin(0.17), 0.0, np.cos(0.17)])
    T_wb = plane_base_poses([1.0], [0.5], [0.4], n, -0.2)[0]
    trained = MapAccumulator(tiago, None, BuildSettings(samples=2_000_000, seed=3)).chunk_samples(0)[:50]
    T_bt = pinocchio_fk(tiago, arm, trained)
    assert np.all(tiago_map.inverse(T_wb @ T_bt[0], T_wb[None]) > 0)
    values = [tiago_map.inverse(T_wb @ T, T_wb[None])[0] for T in T_bt]
    np.testing.assert_array_equal(values, tiago_map.reachability(T_bt))


def test_min_over_targets_and_arm_combinations(pr2, rng):
    left = build_map(pr2, "left", BuildSettings(samples=600_000, seed=1))
    right = build_map(pr2, "right", BuildSettings(samples=600_000, seed=1))
    # Bases behind the targets, roughly facing them (+x), where PR2's arms work.
    bases = BasePose.batch_matrix(np.c_[rng.uniform(-0.8, 0.0, 500), rng.uniform(-0.5, 0.5, 500),
                                        rng.uniform(-0.6, 0.6, 500)])  # fmt: skip
    targets = np.repeat(np.eye(4)[None], 2, axis=0)  # gripper x axis forward, z up
    targets[:, :3, 3] = [[0.6, 0.05, 0.8], [0.55, -0.05, 0.75]]
    v0, v1 = (left.inverse(t, bases) for t in targets)
    np.testing.assert_array_equal(inverse_reachability(left, targets, bases), np.minimum(v0, v1))
    r0 = right.inverse(targets[0], bases)
    either = ArmCombination((left, right), "any").inverse(targets[0], bases)
    both = ArmCombination((left, right), "both").inverse(targets[0], bases)
    np.testing.assert_array_equal(either, np.maximum(v0, r0))
    np.testing.assert_array_equal(both, np.minimum(v0, r0))
    assert (either > 0).sum() > (both > 0).sum() > 0
    with pytest.raises(InputError, match="valid: any, both"):
        ArmCombination((left, right), "either")  # type: ignore[arg-type]


def test_bad_query_shapes_and_values(tiago_map):
    with pytest.raises(InputError, match="shape"):
        tiago_map.reachability(np.eye(3))
    T = np.eye(4)
    T[0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        tiago_map.inverse(T, np.eye(4)[None])


def test_manipulability_is_the_best_per_cell(tiago):
    settings = BuildSettings(samples=3000, seed=5, manipulability=True)
    m = build_map(tiago, None, settings)
    arm = tiago.arm()
    Q = MapAccumulator(tiago, None, settings).chunk_samples(0)
    model, data = tiago.model, tiago.model.createData()
    tcp = model.getFrameId(arm.tcp_frame)
    cols = [model.joints[model.getJointId(j)].idx_v for j in arm.joint_names]
    best: dict[int, float] = {}
    cells = m.grid.cell_index(pinocchio_fk(tiago, arm, Q))
    for q, cell in zip(Q, cells, strict=True):  # oracle: pinocchio's Jacobian, Yoshikawa's measure
        J = pin.computeFrameJacobian(model, data, arm.to_pinocchio(q, tiago.q_reference), tcp,
                                     pin.LOCAL_WORLD_ALIGNED)[:, cols]  # fmt: skip
        best[int(cell)] = max(best.get(int(cell), 0.0), float(np.sqrt(max(0.0, np.linalg.det(J @ J.T)))))
    assert m.manipulability is not None
    expected = np.array([best[int(c)] for c in m.cells])
    np.testing.assert_allclose(m.manipulability, expected, rtol=1e-5, atol=1e-9)
    assert expected.max() > 0


def test_settings_validation(planar3):
    with pytest.raises(InputError, match="samples"):
        BuildSettings(samples=0)
    with pytest.raises(InputError, match="voxel size"):
        build_map(planar3, None, BuildSettings(samples=10, voxel_size=5.0))


def test_self_collision_drops_samples(tiago):
    m = build_map(tiago, None, BuildSettings(samples=400, self_collision=True, seed=2))
    assert 0 < m.info.dropped_self_collision < 400
    assert int(m.counts.sum()) == 400 - m.info.dropped_self_collision


def test_fused_plane_lookup_equals_explicit_poses(tiago_map, rng):
    # The fused kernel against the plain path: build the poses, then the generic inverse lookup.
    target = np.eye(4)
    target[:3, 3] = [0.6, 0.3, 0.9]
    n = np.array([0.1, -0.05, 1.0])
    xy = rng.uniform(-1.0, 1.5, (5000, 2))
    gamma = rng.uniform(-np.pi, np.pi, 5000)
    fused = tiago_map.inverse_on_plane(target, xy, gamma, n, -0.3)
    explicit = tiago_map.inverse(target, plane_base_poses(xy[:, 0], xy[:, 1], gamma, n, -0.3))
    np.testing.assert_array_equal(fused, explicit)
    assert (fused > 0).sum() > 50


def test_single_pose_value_and_small_batches(tiago, tiago_map, rng):
    # Oracle: pinocchio FK of samples the build drew (in the map) and poses beyond any reach (0).
    arm = tiago.arm()
    trained = MapAccumulator(tiago, None, BuildSettings(samples=2_000_000, seed=3)).chunk_samples(0)[:300]
    T = pinocchio_fk(tiago, arm, trained)
    far = np.repeat(np.eye(4)[None], 2, axis=0)
    far[:, :3, 3] = [[2.5, 0, 1], [0, 0, 4]]
    values = np.array([tiago_map.value(np.ascontiguousarray(t)) for t in T])
    assert np.all(values > 0)
    assert [tiago_map.value(t) for t in far] == [0.0, 0.0]
    assert tiago_map.value(T[0].tolist()) == values[0]  # any array-like of one pose
    # serial (small batch) and parallel (large batch) kernels give the same values
    big = np.tile(T, (10, 1, 1))  # above SERIAL_BELOW: the parallel kernel
    np.testing.assert_array_equal(tiago_map.reachability(big)[:300], values)
    np.testing.assert_array_equal(tiago_map.reachability(T[:5]), values[:5])
    bad = T[0].copy()
    bad[1, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        tiago_map.value(bad)
    with pytest.raises(InputError, match="one pose"):
        tiago_map.value(T[:2])


def test_cache_keeps_maps_of_different_cells_apart():
    """A self-collision, manipulability or certified map never reuses the plain map's cache file."""
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.cache import cached_map_path
    from baseplace.robots.model import Robot

    robot = Robot("tiago")
    plain = cached_map_path(robot, BuildSettings())
    assert cached_map_path(robot, BuildSettings()) == plain
    others = {
        cached_map_path(robot, BuildSettings(self_collision=True)),
        cached_map_path(robot, BuildSettings(manipulability=True)),
        cached_map_path(robot, BuildSettings(certify=5)),
    }
    assert plain not in others and len(others) == 3


def test_reached_voxels_and_horizontal_reach_against_every_cell(tiago_map):
    """The distinct voxels of the cells (np.unique as the oracle) and the farthest one's reach."""
    m = tiago_map
    voxels = np.unique(m.cells // m.grid.n_orientations)
    assert np.array_equal(m.reached_voxels, voxels)
    offset, _ = m.tables
    assert np.array_equal(np.flatnonzero(offset >= 0), voxels)
    centres = m.grid.voxel_centre(voxels)
    far = np.hypot(centres[:, 0], centres[:, 1]).max() + m.grid.voxel_size * np.sqrt(0.5)
    assert m.horizontal_reach == pytest.approx(far, abs=1e-12)
