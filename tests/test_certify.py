"""Certified maps: sparse cells resolved by IK; checked against an independent IK and pinocchio FK."""

from __future__ import annotations

import json

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.reachability.build import BuildSettings, MapAccumulator, build_map
from baseplace.reachability.certify import CertifySettings, poses_in_cells
from baseplace.reachability.storage import load_map, save_map
from baseplace.robots.ik import DampedLeastSquaresIK
from test_kinematics import pinocchio_fk

# the support test off: these tests read certified cells whole
COARSE = {
    "samples": 300_000,
    "seed": 5,
    "voxel_size": 0.2,
    "orientation_resolution": 1.6,
    "support_threshold": 0.0,
}


@pytest.fixture(scope="module")
def maps(tiago):
    plain = build_map(tiago, None, BuildSettings(**COARSE))
    certified = build_map(tiago, None, BuildSettings(**COARSE, certify=3))
    return plain, certified


def test_poses_in_cells_land_in_their_cells(tiago, maps):
    plain, _ = maps
    rng = np.random.default_rng(0)
    cells = plain.cells[rng.choice(len(plain.cells), 500, replace=False)]
    T = poses_in_cells(plain.grid, cells, rng)
    np.testing.assert_array_equal(plain.grid.cell_index(T), cells)
    np.testing.assert_allclose(
        T[:, :3, :3] @ T[:, :3, :3].transpose(0, 2, 1), np.broadcast_to(np.eye(3), (500, 3, 3)), atol=1e-9
    )


def test_certified_cells_are_the_reachable_ones(tiago, maps):
    plain, cert = maps
    info = json.loads(cert.info.certification)
    assert info["below"] == 3 and info["cells_certified"] == int((plain.counts < 3).sum())
    kept = np.isin(plain.cells, cert.cells)
    removed = plain.cells[~kept]
    assert len(removed) == info["cells_removed"] > 0
    assert np.all(plain.counts[~kept] < 3)  # only sparse cells can go
    # Oracle: IK with 80 restarts on other poses (another seed) inside removed and certified cells.
    rng = np.random.default_rng(99)
    ik = DampedLeastSquaresIK(tiago.arm())
    certified_low = cert.cells[np.isfinite(cert.quality)]
    n = min(150, len(removed), len(certified_low))
    _, ok_removed = ik.solve_batch(
        poses_in_cells(plain.grid, rng.choice(removed, n, replace=False), rng), rng
    )
    _, ok_kept = ik.solve_batch(
        poses_in_cells(plain.grid, rng.choice(certified_low, n, replace=False), rng), rng
    )
    assert ok_kept.mean() > ok_removed.mean() + 0.1  # coarse cells: most are partly reachable
    # Every consumer reads the certified cells: removed cells read 0, kept ones their index.
    T = poses_in_cells(plain.grid, removed[:200], rng)
    assert np.all(cert.reachability(T) == 0)
    assert all(cert.value(np.ascontiguousarray(t)) == 0 for t in T)
    assert np.all(cert.inverse(T[0], np.eye(4)[None]) == 0)
    quality = json.loads(cert.info.quality)
    assert 0 < quality["recall"] <= 1 and 0 < quality["precision"] <= 1


def test_build_samples_in_kept_cells_stay_reachable(tiago, maps):
    # Oracle: pinocchio FK of the build's own samples; they fall in certified or dense cells.
    _, cert = maps
    Q = MapAccumulator(tiago, None, BuildSettings(**COARSE)).chunk_samples(0)[:3000]
    T = pinocchio_fk(tiago, tiago.arm(), Q)
    cells = cert.grid.cell_index(T)
    in_map = np.isin(cells, cert.cells)
    assert in_map.mean() > 0.95
    np.testing.assert_array_equal(cert.reachability(T) > 0, in_map)


def test_certified_map_roundtrip(tiago, maps, tmp_path):
    _, cert = maps
    save_map(cert, tmp_path / "c.rmap")
    back = load_map(tmp_path / "c.rmap", tiago)
    np.testing.assert_array_equal(back.cells, cert.cells)
    np.testing.assert_array_equal(back.quality, cert.quality)
    assert back.info == cert.info


def test_certify_settings_validation():
    with pytest.raises(InputError, match="certify"):
        BuildSettings(certify=-1)
    with pytest.raises(InputError, match="poses"):
        CertifySettings(poses=0)
