import math

import numpy as np
import pytest
from scipy.special import jv

from prefilter.glints.pndf import pndf_image
from prefilter.glints.wave import cmf, ndf
from prefilter.glints.wave import heightfield as hfm

R, S = 64, 0.25
PITCH = 2 * S / R
CENTERS = -S + (np.arange(R) + 0.5) * PITCH


def test_flat_patch_is_the_windows_diffraction_pattern():
    hf = hfm.heightfield(np.zeros((48, 48)), 0.25e-6)
    sigma = 4.0
    exact = ndf.spectral_images(hf, [[24.5, 20.5]], sigma, R, S, supersample=6)[0]
    default = ndf.spectral_images(hf, [[24.5, 20.5]], sigma, R, S)[0]
    for lam, D, D1 in zip(cmf.WAVELENGTHS, exact, default):
        sd = ndf.diffraction_std(lam, sigma * hf.texel_size)
        assert sd == pytest.approx(lam / (8 * math.pi * sigma * 0.25e-6))
        # pixel means of the Gaussian N(0, sd^2 I) in s
        from scipy.special import erf
        edges = np.linspace(-S, S, R + 1) / (math.sqrt(2) * sd)
        m = 0.5 * np.diff(erf(edges)) / PITCH
        expect = np.outer(m, m)
        assert np.abs(D - expect).max() <= 2e-3 * expect.max()
        # the default sampling (2 points per std) gives pixel means to ~1 %
        assert np.abs(D1 - expect).max() <= 2e-2 * expect.max()
        assert D.sum() * PITCH**2 == pytest.approx(1.0, abs=1e-5)


def test_sinusoidal_grating_orders_at_the_grating_equation():
    """h = a sin(2 pi x / L): orders m at s = m lambda / (2 L) (Littrow: 2 sin(theta) = m lambda /
    L) with powers J_m(2 k a)^2."""
    dx, period, a, lam = 0.5e-6, 8, 0.05e-6, 500e-9
    x = np.arange(64) + 0.5
    hf = hfm.heightfield(np.tile(a * np.sin(2 * np.pi * x / period), (64, 1)), dx)
    D = ndf.spectral_images(hf, [[32.5, 32.5]], 12.0, R, S, [lam])[0, 0]
    prof = D.sum(axis=0) * PITCH
    for m in range(-3, 4):
        sm = m * lam / (2 * period * dx)
        sel = np.abs(CENTERS - sm) < 0.02
        power = prof[sel].sum() * PITCH
        assert power == pytest.approx(jv(m, 4 * np.pi / lam * a) ** 2, abs=2e-3)
        assert (prof[sel] * CENTERS[sel]).sum() / prof[sel].sum() == pytest.approx(sm, abs=1e-4)
    assert np.abs(D.sum(axis=1)[np.abs(CENTERS) > 0.03]).max() < 1e-3 * D.max()  # no y orders


def test_short_wavelengths_approach_the_geometric_pndf():
    hf = hfm.isotropic_noise(48, rms=0.15e-6, correlation=6.0, seed=2)
    geo = pndf_image(hfm.normal_map(hf), [24.5, 24.5], 4.0, R, S, 0.002)
    from scipy.ndimage import gaussian_filter

    d = []
    for lam in (400e-9, 100e-9, 50e-9):
        w = ndf.spectral_images(hf, [[24.5, 24.5]], 4.0, R, S, [lam])[0, 0]
        # L1 of the densities seen at 2 NDF pixels' resolution (the speckle grain shrinks with
        # the wavelength; the P-NDF's element model differs from the smooth surface by ~8 %)
        d.append(np.abs(gaussian_filter(w, 2, mode="constant")
                        - gaussian_filter(geo, 2, mode="constant")).sum() * PITCH**2)
    assert d[0] > d[1] > d[2]
    assert d[2] < 0.1


def test_energy_of_every_image_within_one_percent():
    # support 0.5: the whole pattern inside the image (rms slope 0.07 per axis)
    hf = hfm.isotropic_noise(64, rms=0.05e-6, correlation=4.0, texel_size=0.25e-6, seed=1)
    sp = ndf.spectral_images(hf, [[10.5, 3.5], [40.5, 33.5]], 4.0, R, 0.5)
    pitch2 = (1.0 / R) ** 2
    assert np.all(np.abs(sp.sum(axis=(-1, -2)) * pitch2 - 1.0) < 0.01)
    rgb = cmf.spectral_to_rgb(sp)
    assert rgb.min() >= 0
    assert np.all(np.abs(rgb.sum(axis=(-1, -2)) * pitch2 - 1.0) < 0.01)


def test_rgb_weights_white_and_cmf_values():
    w = cmf.rgb_weights()
    assert np.allclose(w.sum(axis=1), 1.0)
    # Wyman et al. 2013 fit at the peak of y-bar: ~1.0 at 555-570 nm
    expect = 0.821 + 0.286 * np.exp(-0.5 * (37.9 / 31.1) ** 2)
    assert cmf.cie_xyz(568.8e-9)[1] == pytest.approx(expect)
    flat = np.ones((8, 4, 4))
    assert np.allclose(cmf.spectral_to_rgb(flat), 1.0)
