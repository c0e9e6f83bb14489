"""The sensor noise read off a cloud's surfaces when no support plane is fitted (the clearance's default).

Oracle: the noise the clouds are generated with.
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.world.sensor_resolution import MIN_CLEARANCE, chi2_quantile, derived_clearance, surface_noise


def _plane(sigma: float, rng: np.random.Generator) -> np.ndarray:
    X, Y = np.meshgrid(np.arange(0, 1, 0.01), np.arange(0, 1, 0.01))
    return np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)] + rng.normal(0.0, sigma, (X.size, 3))


@pytest.mark.parametrize("sigma", [0.001, 0.002, 0.003])
def test_the_noise_of_a_flat_scan(sigma):
    noise = surface_noise(_plane(sigma, np.random.default_rng(1)))
    assert min(noise.fits[0], noise.fits[2]) > 1000
    assert noise.vertical == pytest.approx(sigma, rel=0.15)
    assert noise.worst == pytest.approx(sigma, rel=0.15)


def test_a_cluttered_noise_free_scene_has_no_noise_and_a_noisy_one_has_its_own():
    """A tray of objects on a pedestal: edges everywhere, so a median of local fits read 3-7 mm here."""
    scene = generate_scene(SceneSettings(n_planes=0), np.random.default_rng(7))
    clean = scene.sample_cloud(np.random.default_rng(0), sigma=0.0)
    noisy = scene.sample_cloud(np.random.default_rng(0), sigma=0.003)
    near = lambda p: p[np.hypot(*(p[:, :2] - np.asarray(scene.box.center)).T) <= 0.8]  # noqa: E731
    assert surface_noise(near(clean)).worst < 0.0005
    assert surface_noise(near(noisy)).worst == pytest.approx(0.003, rel=0.25)


def test_the_derived_clearance_without_a_plane_is_three_sigma_of_the_surfaces():
    metres, note = derived_clearance(None, _plane(0.003, np.random.default_rng(2)))
    assert metres == pytest.approx(0.009, rel=0.15)
    assert note.startswith("3 sigma of the surfaces' noise")
    metres, note = derived_clearance(None, _plane(0.0, np.random.default_rng(2)))
    assert metres == MIN_CLEARANCE and "at least 3 mm" in note
    metres, note = derived_clearance(None, np.zeros((3, 3)))
    assert note.startswith("default")


@pytest.mark.parametrize("dof", [1, 2, 5, 13, 40])
@pytest.mark.parametrize("q", [0.01, 0.2, 0.5, 0.95])
def test_chi2_quantile_is_scipy_stats_chi2_ppf(q, dof):
    from scipy.stats import chi2

    assert chi2_quantile(q, dof) == pytest.approx(chi2.ppf(q, dof), rel=1e-12)
