from __future__ import annotations

import healpy
import numba as nb
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chisquare

from baseplace.errors import InputError
from baseplace.geometry.healpix import ang2pix_ring, pix2ang_ring
from baseplace.reachability.grid import SE3Grid, orientation_bins_for


@nb.njit
def _ang2pix_many(nside, z, phi):
    out = np.empty(len(z), dtype=np.int64)
    for i in range(len(z)):
        out[i] = ang2pix_ring(nside, z[i], phi[i])
    return out


@pytest.mark.parametrize("nside", [1, 2, 3, 5, 8, 13])
def test_healpix_matches_healpy(nside, rng):
    z = rng.uniform(-1, 1, 50_000)
    phi = rng.uniform(0, 2 * np.pi, 50_000)
    z[:10], z[10:20], z[20:30], z[30:40] = 1.0, -1.0, 2 / 3, -2 / 3
    np.testing.assert_array_equal(_ang2pix_many(nside, z, phi), healpy.ang2pix(nside, np.arccos(z), phi))
    zc, phic = pix2ang_ring(nside)
    theta, phi_ref = healpy.pix2ang(nside, np.arange(12 * nside * nside))
    np.testing.assert_allclose(zc, np.cos(theta), atol=1e-12)
    np.testing.assert_allclose(phic, phi_ref, atol=1e-12)


def _as_T(R, p=None):
    T = np.zeros((len(R), 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = 0.0 if p is None else p
    T[:, 3, 3] = 1.0
    return T


def test_default_orientation_bins_are_at_most_the_resolution():
    nside, n_twist = orientation_bins_for(0.8)
    assert (nside, n_twist) == (2, 8)
    assert np.sqrt(4 * np.pi / (12 * nside**2)) <= 0.8 and 2 * np.pi / n_twist <= 0.8
    with pytest.raises(InputError, match="orientation resolution"):
        orientation_bins_for(0.0)


@pytest.mark.parametrize("resolution", [0.8, 0.5, 1.2])
def test_orientation_bins_have_equal_haar_measure(resolution):
    # Uniform random rotations (Haar measure, scipy) must fill every bin equally.
    grid = SE3Grid.covering([-0.1] * 3, [0.1] * 3, 0.05, resolution)
    R = Rotation.random(400 * grid.n_orientations, random_state=1).as_matrix()
    bins = grid.cell_index(_as_T(R)) % grid.n_orientations
    counts = np.bincount(bins, minlength=grid.n_orientations)
    assert counts.min() > 0
    assert chisquare(counts).pvalue > 1e-3


def test_orientation_bins_are_compact(rng):
    # Rotations in one bin lie within a bounded angle of the bin centre, also next to the poles.
    grid = SE3Grid.covering([-0.1] * 3, [0.1] * 3, 0.05, 0.8)
    R = Rotation.random(200_000, random_state=2)
    bins = grid.cell_index(_as_T(R.as_matrix())) % grid.n_orientations
    centres = Rotation.from_matrix(grid.orientation_centre(bins))
    angle = (centres.inv() * R).magnitude()
    assert np.percentile(angle, 99.9) < 0.8  # half-diagonal of a 0.51 x 0.51 x 0.79 rad cell ~0.55
    centre_bins = grid.cell_index(_as_T(grid.orientation_centre(np.arange(grid.n_orientations))))
    np.testing.assert_array_equal(centre_bins % grid.n_orientations, np.arange(grid.n_orientations))


def test_positions_outside_the_box_are_minus_one():
    grid = SE3Grid.covering([0, 0, 0], [1, 1, 1], 0.05, 0.8)
    T = _as_T(
        np.repeat(np.eye(3)[None], 3, axis=0),
        np.array([[0.5, 0.5, 0.5], [1.2, 0.5, 0.5], [-0.01, 0, 0]]),
    )
    idx = grid.cell_index(T)
    assert idx[0] >= 0 and idx[1] == -1 and idx[2] == -1
    centre = grid.cell_centre(idx[:1])[0]
    assert np.all(np.abs(centre[:3, 3] - 0.5) <= 0.025 + 1e-12)
