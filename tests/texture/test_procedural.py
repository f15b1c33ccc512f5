"""Procedural textures: statistics against their parameters (within measured sampling error),
analytic slopes against finite differences, the per-level noise variance against a direct sum of
the covariance function and against box-filtered instances, determinism and periodicity."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.texture import height_map, noise, noise_level_variance, normal_map


def _slopes(n):
    return -n[..., :2] / n[..., 2:]


def _cov(s):
    s = s.reshape(-1, 2)
    return s.T @ s / len(s)  # about the process mean 0


def _mean_and_se(samples):
    a = np.asarray(samples)
    return a.mean(0), a.std(0, ddof=1) / np.sqrt(len(a))


@pytest.mark.parametrize("kind", ["gaussian", "anisotropic", "brushed", "scratches", "flakes"])
def test_unit_normals_deterministic_and_seed_dependent(kind):
    a = normal_map(kind, 64, seed=5)
    b = normal_map(kind, 64, seed=5)
    c = normal_map(kind, 64, seed=6)
    assert a.shape == (64, 64, 3) and a.dtype == np.float64
    assert np.allclose(np.linalg.norm(a, axis=-1), 1.0, atol=1e-12)
    assert np.all(a[..., 2] > 0)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


def test_gaussian_rms_slope_matches_parameter():
    target = 0.3
    vals = [np.mean(np.sum(_slopes(normal_map("gaussian", 128, s, rms_slope=target,
                                              corr_length=4.0)) ** 2, -1)) for s in range(10)]
    m, se = _mean_and_se(vals)
    assert se < 0.03 * target**2  # the test has power to see a few-percent error
    assert abs(m - target**2) < 4 * se


def test_anisotropic_slope_covariance_matches_parameter():
    cov = np.array([[0.04, 0.015], [0.015, 0.02]])
    vals = [_cov(height_map("anisotropic", 128, s, cov=cov, corr_length=4.0).slopes)
            for s in range(10)]
    m, se = _mean_and_se(vals)
    assert np.all(se < 0.003)
    assert np.all(np.abs(m - cov) < 4 * se + 1e-12)


def test_slopes_are_derivatives_of_height_and_periodic():
    h = height_map("gaussian", 128, 2, rms_slope=0.5, corr_length=6.0)
    z = h.height
    # 4th-order periodic central differences: exact up to O(k^5) for this smooth field, and the
    # np.roll wrap checks periodicity (a non-periodic field would break at the border).
    fx = (-np.roll(z, -2, 1) + 8 * np.roll(z, -1, 1) - 8 * np.roll(z, 1, 1) + np.roll(z, 2, 1)) / 12
    fy = (-np.roll(z, -2, 0) + 8 * np.roll(z, -1, 0) - 8 * np.roll(z, 1, 0) + np.roll(z, 2, 0)) / 12
    scale = np.abs(h.slopes).max()
    assert np.abs(fx - h.slopes[..., 0]).max() < 0.01 * scale
    assert np.abs(fy - h.slopes[..., 1]).max() < 0.01 * scale


def test_gaussian_slopes_are_gaussian():
    s = height_map("gaussian", 256, 1, rms_slope=0.4, corr_length=4.0).slopes[..., 0].ravel()
    kurt = np.mean(s**4) / np.mean(s**2) ** 2
    assert abs(kurt - 3.0) < 0.3


def test_brushed_grooves_run_along_x():
    vals = [_cov(height_map("brushed", 128, s, rms_slope=0.2, length=32.0, width=2.0).slopes)
            for s in range(6)]
    m, se = _mean_and_se(vals)
    # slope covariance ratio is (width / length)^2 by construction of the correlation
    assert m[1, 1] > 50 * m[0, 0]
    assert abs(np.trace(m) - 0.04) < 4 * np.sqrt(se[0, 0] ** 2 + se[1, 1] ** 2)


def test_flakes_piecewise_constant_with_parameter_statistics():
    n = normal_map("flakes", 256, 3, flake_size=8.0, rms_slope=0.4)
    flakes = np.unique(n.reshape(-1, 3), axis=0)
    assert abs(len(flakes) - 32 * 32) <= 32  # about one flake per 8x8 cell (few hidden ones)
    s = _slopes(flakes)
    # per-flake slopes ~ N(0, 0.08 I): the sample variance of 1000 draws has rel. sd sqrt(2/1000)
    var = np.mean(s**2, 0)
    assert np.all(np.abs(var - 0.08) < 4 * 0.08 * np.sqrt(2 / len(s)))


def test_scratches_flat_base_and_grooves():
    n0 = normal_map("scratches", 64, 0, count=0)
    assert np.array_equal(n0, np.broadcast_to([0.0, 0.0, 1.0], n0.shape))
    n = normal_map("scratches", 128, 0, count=10, width=1.0, depth=1.0)
    tilted = n[..., 2] < 0.999
    assert 0.005 < tilted.mean() < 0.3
    # a Gaussian groove of depth d, width w has max slope d / w exp(-1/2)
    assert _slopes(n).max() < 10 * np.exp(-0.5)


def test_noise_level_variance_matches_covariance_sum():
    n, l = 64, 3.0
    pred = noise_level_variance(n, l, sigma=2.0)
    # Direct: the variance of an m x m block mean is the mean of C over all texel pairs; C is
    # separable, C = sigma^2 g(dx) g(dy) with g(d) = exp(-d^2 / l^2) (periodic distance d).
    i_all = np.arange(n)
    g = np.exp(-(np.minimum(i_all, n - i_all) ** 2) / l**2)
    for L, v in enumerate(pred):
        i = np.arange(2**L)
        direct = 2.0**2 * g[np.abs(i[:, None] - i[None, :])].mean() ** 2
        assert v == pytest.approx(direct, rel=1e-6), L


def test_noise_instance_variance_per_level():
    n, l = 128, 3.0
    pred = noise_level_variance(n, l)
    per_seed = []
    for seed in range(12):
        x = noise(n, seed, l)
        per_seed.append([np.mean(x.reshape(n // 2**L, 2**L, n // 2**L, 2**L).mean((1, 3)) ** 2)
                         for L in range(5)])
    m, se = _mean_and_se(per_seed)
    assert np.all(np.abs(m - pred[:5]) < 4 * se + 1e-3 * pred[:5])
    assert pred[0] == pytest.approx(1.0)
    assert np.all(np.diff(pred) < 0)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: normal_map("plaid", 32), ["kind", "plaid"]),
        (lambda: normal_map("gaussian", 32, rms=0.2), ["rms", "rms_slope"]),
        (lambda: normal_map("gaussian", 32, rms_slope=-1), ["rms_slope", "-1"]),
        (lambda: height_map("anisotropic", 32, cov=[[1, 2], [2, 1]]), ["cov", "positive"]),
        (lambda: normal_map("gaussian", 0), ["size"]),
        (lambda: noise(32, seed=None), ["seed"]),
        (lambda: noise_level_variance(48), ["size", "power of two"]),
    ],
)
def test_bad_parameters_raise_clear_errors(call, words):
    with pytest.raises(PrefilterError) as e:
        call()
    for w in words:
        assert w in str(e.value)
