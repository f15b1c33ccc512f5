"""Compiled shading kernels against the NumPy path and brute-force footprint averages."""

import numpy as np
import pytest
from scipy.special import log_ndtr, ndtr

from prefilter.colormap import prefilter_table
from prefilter.colormap.height import filter_height_footprint, smith_lambda_direction
from prefilter.colormap import kernels
from prefilter.colormap.kernels import PackedChain, shade_height, shade_noise, shade_texture
from prefilter.colormap.texture import NoiseStd, filter_noise, footprint_stats, moments_mip
from prefilter.texture.mip import MipChain
from prefilter.texture.procedural import noise

N = 64


def _footprints(n, seed):
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-1.0, 2.0, (n, 2))
    # footprints from 0.2 to ~40 texels, anisotropic up to ~10:1, random orientations
    scale = np.exp(rng.uniform(np.log(0.2), np.log(40.0), n)) / N
    ang = rng.uniform(0, np.pi, n)
    ratio = np.exp(rng.uniform(0, np.log(10), n))
    rot = np.stack([np.stack([np.cos(ang), -np.sin(ang)], -1),
                    np.stack([np.sin(ang), np.cos(ang)], -1)], -2)
    diag = np.zeros((n, 2, 2))
    diag[:, 0, 0] = scale
    diag[:, 1, 1] = scale / ratio
    return uv, rot @ diag


def _table():
    return prefilter_table(lambda v: np.stack([np.sin(3 * v), np.tanh(2 * v), v * v / 9], -1),
                           (-4.0, 4.0), 2.0, size=128, edge="mirror")


@pytest.mark.parametrize("aniso", [False, True])
def test_texture_kernel_matches_numpy(aniso):
    f = noise(N, seed=3, corr_length=2.0)
    table = _table()
    uv, dudv = _footprints(3000, 1)
    chain = moments_mip(f)
    mean, var = footprint_stats(chain, uv, dudv, anisotropic=aniso)
    want = table.lookup(mean, np.sqrt(var))
    got = shade_texture(table, PackedChain(chain), uv, dudv, anisotropic=aniso)
    np.testing.assert_allclose(got, want, atol=1e-9)
    naive = shade_texture(table, PackedChain(MipChain(f)), uv, dudv, filtered=False,
                          anisotropic=aniso)
    np.testing.assert_allclose(naive, table.naive(mean), atol=1e-9)


def test_noise_kernel_matches_numpy():
    f = noise(N, seed=5, corr_length=2.0)
    table = _table()
    uv, dudv = _footprints(3000, 2)
    ns = NoiseStd.from_procedural(N, 2.0)
    want, want_naive = filter_noise(table, MipChain(f), ns, uv, dudv, anisotropic=True)
    packed = PackedChain(MipChain(f))
    np.testing.assert_allclose(shade_noise(table, packed, ns, uv, dudv), want, atol=1e-9)
    np.testing.assert_allclose(shade_noise(table, packed, ns, uv, dudv, filtered=False),
                               want_naive, atol=1e-9)


def test_height_kernel_matches_numpy_and_block_averages():
    rng = np.random.default_rng(0)
    x = noise(N, seed=7, corr_length=2.0)
    table = prefilter_table(lambda v: np.stack([0.5 + 0.5 * np.tanh(3 * v), np.cos(v)], -1),
                            (-4.5, 4.5), 1.5, size=256)
    uv, dudv = _footprints(2000, 3)
    t = np.radians(rng.uniform(0, 85, (2, 2000)))
    p = rng.uniform(0, 2 * np.pi, (2, 2000))
    w = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    cov = np.array([[0.12, 0.02], [0.02, 0.08]])
    chain = moments_mip(x)
    mu, var = footprint_stats(chain, uv, dudv, anisotropic=True)
    lo = smith_lambda_direction(w[0], cov)
    li = smith_lambda_direction(w[1], cov)
    want = filter_height_footprint(table, mu, np.sqrt(var), lo, li)
    got = shade_height(table, PackedChain(chain), uv, dudv, w[0], w[1], cov)
    np.testing.assert_allclose(got, want, atol=1e-6)  # tabulated log2, Phi and Mills ratio
    naive = shade_height(table, PackedChain(MipChain(x)), uv, dudv, w[0], w[1], cov,
                         filtered=False)
    np.testing.assert_allclose(naive, ((1 + lo) / (1 + lo + li))[:, None] * table.naive(mu),
                               atol=1e-9)


def test_texture_kernel_against_block_averages():
    # aligned 8 x 8 footprints of near-white Gaussian data: filtered ~ the block's colour average
    f = noise(N, seed=9, corr_length=1.0)
    table = _table()
    k = N // 8
    c = (np.arange(k) + 0.5) / k
    uv = np.stack(np.meshgrid(c, c), -1).reshape(-1, 2)
    dudv = np.broadcast_to(np.eye(2) * 8 / N, (uv.shape[0], 2, 2))
    truth = table.naive(f.reshape(k, 8, k, 8).transpose(0, 2, 1, 3).reshape(-1, 64)).mean(1)
    got = shade_texture(table, PackedChain(moments_mip(f)), uv, dudv, anisotropic=False)
    naive = shade_texture(table, PackedChain(MipChain(f)), uv, dudv, filtered=False)
    err = np.sqrt(np.mean((got - truth) ** 2))
    assert err < 0.3 * np.sqrt(np.mean((naive - truth) ** 2))


@pytest.mark.parametrize("scale", [1.0, 3.0])
def test_height_kernel_relative_error_grazing(scale):
    # heights 3x the table's unit and views to 89.5 degrees reach L ~ 16, the deep-shadow branch
    # (z < -3) and Lambda_o < 1e-4 (below the probit grid): relative agreement with the NumPy path
    rng = np.random.default_rng(11)
    x = noise(N, seed=7, corr_length=2.0) * scale
    table = prefilter_table(lambda v: np.stack([0.5 + 0.5 * np.tanh(3 * v), 1.2 + np.cos(v)], -1),
                            (-4.5 * scale, 4.5 * scale), 1.5 * scale, size=256)
    n = 6000
    uv, dudv = _footprints(n, 4)
    t = np.radians(rng.uniform(0, 89.5, (2, n)))
    p = rng.uniform(0, 2 * np.pi, (2, n))
    w = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    cov = np.array([[0.12, 0.02], [0.02, 0.08]])
    chain = moments_mip(x)
    mu, var = footprint_stats(chain, uv, dudv, anisotropic=True)
    lo = smith_lambda_direction(w[0], cov)
    li = smith_lambda_direction(w[1], cov)
    assert (lo < 1e-4).any() and (lo + li).max() > 10
    want = filter_height_footprint(table, mu, np.sqrt(var), lo, li)
    got = shade_height(table, PackedChain(chain), uv, dudv, w[0], w[1], cov)
    big = np.abs(want) > 1e-2  # colour 1 is >= 0.2 before visibility: relative where it is lit
    assert big.sum() > n
    assert np.max(np.abs(got - want)[big] / np.abs(want[big])) < 1e-5
    assert np.max(np.abs(got - want)) < 1e-6


def test_log2_fast_against_numpy():
    x = np.exp(np.random.default_rng(2).uniform(-40.0, 40.0, 5000))
    got = np.array([kernels._log2_fast(v, kernels._LOG2_M) for v in x])
    assert np.max(np.abs(got - np.log2(x))) < 2e-7
    assert kernels._log2_fast(1.0, kernels._LOG2_M) == 0.0


def test_phi_mills_tables_against_scipy():
    z = np.linspace(-3.0, 10.0, 40001)
    pm = np.array([kernels._phi_mills(v, kernels._HERMITE) for v in z])
    cdf = np.array([kernels._phi_cdf(v, kernels._HERMITE) for v in z])
    mills = np.exp(-0.5 * z * z - log_ndtr(z)) / np.sqrt(2 * np.pi)
    assert np.max(np.abs(pm[:, 0] - ndtr(z)) / ndtr(z)) < 1e-6
    assert np.max(np.abs(cdf - ndtr(z)) / ndtr(z)) < 1e-6
    assert np.max(np.abs(pm[:, 1] - mills)) < 1e-8
