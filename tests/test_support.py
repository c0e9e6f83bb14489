"""The support test of reachability maps: checked against healpy, an independent interpolation, and IK."""

from __future__ import annotations

import dataclasses
import json

import healpy
import numba as nb
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baseplace.errors import InputError
from baseplace.geometry.healpix import interp_weights_ring
from baseplace.reachability.build import BuildSettings, build_map, support_count
from baseplace.reachability.certify import poses_in_cells
from baseplace.reachability.rmap import MapInfo, ReachabilityMap
from baseplace.reachability.storage import load_map, save_map
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK

# A coarse grid fills quickly: a mean of ~40 samples per reached cell from 4e6 samples.
COARSE = {"samples": 4_000_000, "seed": 11, "voxel_size": 0.1, "orientation_resolution": 1.2}


@pytest.fixture(scope="module")
def maps(tiago) -> tuple[ReachabilityMap, ReachabilityMap]:
    """(the map with the default support test, the same cells read whole)."""
    supported = build_map(tiago, None, BuildSettings(**COARSE))
    whole = supported.with_support(0, 0.0)
    return supported, whole


@nb.njit
def _weights_many(nside, z, phi):
    pix = np.empty((len(z), 4), dtype=np.int64)
    w = np.empty((len(z), 4))
    for i in range(len(z)):
        interp_weights_ring(nside, z[i], phi[i], pix[i], w[i])
    return pix, w


@pytest.mark.parametrize("nside", [1, 2, 3, 5, 8])
def test_sphere_interpolation_matches_healpy(nside, rng):
    z = rng.uniform(-1, 1, 5000)
    phi = rng.uniform(0, 2 * np.pi, 5000)
    z[:5], z[5:10], z[10:15], z[15:20] = 1.0, -1.0, 2 / 3, -2 / 3  # poles and the cap edges
    pix, w = _weights_many(nside, z, phi)
    ref_pix, ref_w = healpy.get_interp_weights(nside, np.arccos(z), phi)
    for i in range(len(z)):  # the same weight per pixel (a pixel can appear twice next to a pole)
        got, ref = np.zeros(12 * nside * nside), np.zeros(12 * nside * nside)
        np.add.at(got, pix[i], w[i])
        np.add.at(ref, ref_pix[:, i], ref_w[:, i])
        np.testing.assert_allclose(got, ref, atol=1e-12)


def reference_support(rmap: ReachabilityMap, T: np.ndarray) -> np.ndarray:
    """The support of poses written out in numpy on healpy's interpolation: the oracle of the kernel."""
    g, info = rmap.grid, rmap.info
    n_orient, shape = g.n_orientations, np.array(g.shape)
    lookup = dict(
        zip(rmap.cells.tolist(), np.minimum(rmap.counts / info.support_count, 1.0).tolist(), strict=True)
    )
    R = T[:, :3, :3]
    z = np.clip(R[:, 2, 2], -1, 1)
    phi = np.arctan2(R[:, 1, 2], R[:, 0, 2]) % (2 * np.pi)
    psi = np.where(
        z >= 0,
        np.arctan2(R[:, 1, 0] - R[:, 0, 1], R[:, 0, 0] + R[:, 1, 1]) - phi,
        phi - np.arctan2(-(R[:, 1, 0] + R[:, 0, 1]), R[:, 1, 1] - R[:, 0, 0]),
    )
    pixels, pixel_w = healpy.get_interp_weights(g.nside, np.arccos(z), phi)
    centre_phi = healpy.pix2ang(g.nside, np.arange(12 * g.nside**2))[1]
    u = (T[:, :3, 3] - np.array(g.origin)) / g.voxel_size - 0.5
    lo = np.floor(u).astype(int)
    frac = u - lo
    out = np.zeros(len(T))
    for i in range(len(T)):
        for a in range(4):
            dphi = (phi[i] - centre_phi[pixels[a, i]] + np.pi) % (2 * np.pi) - np.pi
            t = ((psi[i] + z[i] * dphi) % (2 * np.pi)) * g.n_twist / (2 * np.pi) - 0.5
            k = int(np.floor(t))
            for kk, wk in ((k % g.n_twist, 1 - (t - k)), ((k + 1) % g.n_twist, t - k)):
                o = pixels[a, i] * g.n_twist + kk
                for d in np.ndindex(2, 2, 2):
                    ijk = lo[i] + d
                    if np.any(ijk < 0) or np.any(ijk >= shape):
                        continue
                    wv = np.prod(np.where(np.array(d) == 1, frac[i], 1 - frac[i]))
                    cell = int(np.ravel_multi_index(tuple(ijk), g.shape)) * n_orient + o
                    out[i] += lookup.get(cell, 0.0) * wv * wk * pixel_w[a, i]
    return out


def near_cells(tiago, rmap, n, rng):
    """FK poses of random configurations, moved by up to a cell: inside, across and off the boundary."""
    T = forward_kinematics(tiago.arm(), tiago.arm().sample(rng, n))
    T[:, :3, 3] += rng.normal(0, rmap.grid.voxel_size, (n, 3))
    T[:, :3, :3] = T[:, :3, :3] @ Rotation.from_rotvec(rng.normal(0, 0.5, (n, 3))).as_matrix()
    return T


def test_support_is_the_interpolation_of_the_counts(tiago, maps, rng):
    supported, whole = maps
    assert supported.info.support_count == support_count(supported.counts, 8) >= 2
    assert supported.info.support_threshold == BuildSettings().support_threshold
    tau = supported.info.support_threshold
    T = near_cells(tiago, supported, 3000, rng)
    s = reference_support(supported, T)
    in_cell = whole.reachability(T) > 0
    got = supported.reachability(T) > 0
    decided = np.abs(s - tau) > 1e-9
    expected = in_cell & (s >= tau)
    np.testing.assert_array_equal(got[decided], expected[decided])
    assert 0.05 < (in_cell & ~got).mean() and got.any()  # the test cut something and kept something
    # every way of asking reads the same answer
    assert all(
        supported.value(np.ascontiguousarray(t)) == v
        for t, v in zip(T[:300], supported.reachability(T[:300]), strict=True)
    )
    base = np.eye(4)
    np.testing.assert_array_equal(supported.inverse(T[0], base[None]), supported.reachability(T[:1]))
    plane = supported.inverse_on_plane(T[0], [[0.0, 0.0]], [0.0], [0, 0, 1], 0.0)
    np.testing.assert_array_equal(plane, supported.reachability(T[:1]))


def test_cell_centres_follow_the_cell_floor(maps, rng):
    supported, whole = maps
    cells = supported.cells[rng.choice(len(supported.cells), 2000, replace=False)]
    centre_value = supported.reachability(supported.grid.cell_centre(cells))
    table_value = whole.reachability(supported.grid.cell_centre(cells))
    np.testing.assert_array_equal(centre_value > 0, table_value >= supported.cell_floor)
    assert whole.cell_floor == np.finfo(np.float32).tiny


def test_support_raises_precision_against_ik(tiago, maps):
    # Oracle: IK with restarts on poses drawn uniformly in reached cells; precision over the poses
    # each reading calls reachable. The support test must remove more unreachable poses than reachable.
    supported, whole = maps
    rng = np.random.default_rng(7)
    cells = whole.cells[rng.integers(len(whole.cells), size=600)]
    T = poses_in_cells(whole.grid, cells, rng)
    _, ok = DampedLeastSquaresIK(tiago.arm()).solve_batch(T, rng)
    kept = supported.reachability(T) > 0
    assert ok[kept].mean() > ok.mean() + 0.03
    assert ok[~kept].mean() < ok[kept].mean() - 0.2
    quality = json.loads(supported.info.quality)  # recorded at build time on its own draws
    assert quality["precision"] > 0.5 and quality["recall"] > 0.8


def test_sparse_maps_and_threshold_zero_read_whole_cells(tiago, tiago_map, rng):
    assert tiago_map.info.support_count == 0 and not tiago_map.info.supported  # 2e6 samples: too sparse
    assert tiago_map.info.quality == ""
    off = build_map(tiago, None, BuildSettings(**{**COARSE, "samples": 1_000_000, "support_threshold": 0.0}))
    assert not off.info.supported
    T = near_cells(tiago, off, 500, rng)
    np.testing.assert_array_equal(off.reachability(T) > 0, np.isin(off.grid.cell_index(T), off.cells))
    assert support_count(np.array([3, 4], dtype=np.uint32), 7) == 0
    assert support_count(np.array([4, 4], dtype=np.uint32), 7) == 1
    assert support_count(np.full(5, 30, dtype=np.uint32), 7) == 2
    assert support_count(np.full(5, 30, dtype=np.uint32), 5) == 0  # a 5-joint arm: a thin set in SE(3)


def test_arms_of_fewer_than_six_joints_read_whole_cells(planar3):
    # A planar 3-joint arm reaches a 3D set of poses: the support test would erode it to nothing.
    rmap = build_map(planar3, None, BuildSettings(samples=2_000_000, seed=5))
    assert rmap.counts.mean() > 4 and not rmap.info.supported and rmap.info.quality == ""


def test_support_settings_roundtrip_and_hostile_values(tiago, maps, tmp_path):
    supported, _ = maps
    save_map(supported, tmp_path / "s.rmap")
    back = load_map(tmp_path / "s.rmap", tiago)
    assert back.info == supported.info and back.support == supported.support
    for bad in (
        {"support_count": -1},
        {"support_count": 1.5},
        {"support_threshold": 2.0},
        {"support_threshold": "x"},
    ):
        with pytest.raises(InputError, match="support"):
            dataclasses.replace(supported.info, **bad)
    with pytest.raises(InputError, match="support threshold"):
        BuildSettings(support_threshold=-0.1)
    object.__setattr__(back.info, "support_threshold", 5.0)  # as a hostile file would hold it
    save_map(back, tmp_path / "hostile.rmap")
    with pytest.raises(InputError, match=r"cannot read map .*hostile\.rmap: support_threshold must be"):
        load_map(tmp_path / "hostile.rmap", tiago)
    assert MapInfo("r", "", "a", (), "b", "t", 1, 0).support_count == 0  # old files: no support test


def test_the_jobs_default_sample_count_is_the_builds():
    from baseplace.jobs.inputs import DEFAULT_MAP_SAMPLES

    assert DEFAULT_MAP_SAMPLES == BuildSettings().samples
