"""Colour-mapped textures and noise (Heitz et al. 2013, section 4.2) vs brute-force averages."""

import numpy as np
import pytest

from prefilter.colormap import prefilter_table
from prefilter.colormap.texture import (
    NoiseStd,
    filter_noise,
    filter_texture,
    moments_mip,
    naive_texture,
    texture_stats,
)
from prefilter.errors import PrefilterError
from prefilter.texture.mip import MipChain
from prefilter.texture.procedural import noise

N = 128


def _block_footprints(level):
    """uv at the centres of the level-`level` texels and a footprint of exactly 2^level texels."""
    m = 2**level
    k = N // m
    c = (np.arange(k) + 0.5) / k
    u, v = np.meshgrid(c, c)
    uv = np.stack([u, v], -1)
    dudv = np.broadcast_to(np.eye(2) * m / N, uv.shape[:-1] + (2, 2))
    return uv, dudv, m


def _blocks(a, m):
    k = a.shape[0] // m
    return a.reshape(k, m, k, m).transpose(0, 2, 1, 3).reshape(k, k, m * m)


@pytest.mark.parametrize("level", [0, 2, 4])
def test_stats_equal_block_moments(level):
    f = np.random.default_rng(0).gamma(2.0, 1.0, (N, N))  # skewed, non-Gaussian data
    uv, dudv, m = _block_footprints(level)
    mean, sigma = texture_stats(moments_mip(f), uv, dudv)
    b = _blocks(f, m)
    np.testing.assert_allclose(mean, b.mean(-1), atol=1e-12)
    np.testing.assert_allclose(sigma, b.std(-1), atol=1e-6)


def test_filtered_colour_beats_naive_on_gaussian_data():
    f = noise(N, seed=1, corr_length=1.0)  # near-white Gaussian noise
    cmap = lambda v: np.stack([0.5 + 0.5 * np.sin(3 * v), (v > 0.3).astype(float)], -1)  # noqa
    table = prefilter_table(cmap, (-5.0, 5.0), 2.0, size=256)
    uv, dudv, m = _block_footprints(4)
    chain = moments_mip(f)
    truth = cmap(_blocks(f, m)).mean(-2)  # brute-force average of the colour-mapped texels
    err_f = np.sqrt(np.mean((filter_texture(table, chain, uv, dudv) - truth) ** 2))
    err_n = np.sqrt(np.mean((naive_texture(table, chain, uv, dudv) - truth) ** 2))
    assert err_f < 0.25 * err_n
    assert err_f < 0.05


@pytest.mark.parametrize("level", [1, 3, 5])
def test_noise_std_per_lod_against_an_instance(level):
    # within-block variance of many noise instances against the per-LOD table of the process
    ns = NoiseStd.from_procedural(N, corr_length=4.0, sigma=1.5)
    m = 2**level
    var = np.mean([_blocks(noise(N, seed=s, corr_length=4.0, sigma=1.5), m).var(-1).mean()
                   for s in range(8)])
    # an m x m block sees (m^2 - 1) / m^2 of the texel variance with the biased estimator
    assert var == pytest.approx(ns(level) ** 2, rel=0.05)


def test_noise_std_interpolates_and_clamps():
    ns = NoiseStd([4.0, 3.0, 1.0])
    assert ns(0) == 0.0
    assert ns(0.5) == pytest.approx(np.sqrt(0.5))
    assert ns(10) == pytest.approx(np.sqrt(3.0))


def test_filter_noise_beats_naive():
    f = noise(N, seed=4, corr_length=2.0)
    cmap = lambda v: np.stack([np.cos(4 * v), v**2], -1)  # noqa: E731
    table = prefilter_table(cmap, (-5.0, 5.0), 1.5, size=256)
    # process statistics stand in for the instance's: good once blocks hold many correlation cells
    uv, dudv, m = _block_footprints(4)
    got, naive = filter_noise(table, MipChain(f), NoiseStd.from_procedural(N, 2.0), uv, dudv)
    truth = cmap(_blocks(f, m)).mean(-2)
    assert np.sqrt(np.mean((got - truth) ** 2)) < 0.3 * np.sqrt(np.mean((naive - truth) ** 2))


def test_bad_input_raises():
    with pytest.raises(PrefilterError, match="chain"):
        texture_stats(MipChain(np.zeros((4, 4))), np.zeros((1, 2)), np.eye(2)[None])
    with pytest.raises(PrefilterError, match="level_variance"):
        NoiseStd([-1.0])
