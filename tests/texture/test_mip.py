"""Mip chains against direct block averages, lookups against closed forms, footprint axes against
an SVD, anisotropic filtering against the stripes it must keep or remove."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.texture import (
    MipChain,
    footprint_axes,
    height_map,
    lod_from_footprint,
    moment_chain,
    moments_to_stats,
    normal_map,
)


def _blocks(a, m):
    h, w = a.shape[:2]
    return a.reshape(h // m, m, w // m, m, -1).mean((1, 3))


def test_normal_mips_are_unnormalised_box_averages():
    n = normal_map("gaussian", 64, 1, rms_slope=0.6, corr_length=2.0)
    chain = MipChain(n)
    assert chain.n_levels == 7
    for level in range(chain.n_levels):
        assert np.allclose(chain.levels[level], _blocks(n, 2**level), atol=1e-14)
    lengths = np.linalg.norm(chain.levels[3], axis=-1)
    assert lengths.max() < 1.0 - 1e-3  # averaging disagreeing normals shortens them


def test_non_square_chain():
    a = np.random.default_rng(0).uniform(size=(4, 16, 2))
    chain = MipChain(a)
    assert [lv.shape[:2] for lv in chain.levels] == [(4, 16), (2, 8), (1, 4), (1, 2), (1, 1)]
    assert np.allclose(chain.levels[-1][0, 0], a.mean((0, 1)))


def test_lookup_closed_forms():
    rng = np.random.default_rng(3)
    tex = rng.uniform(size=(8, 8, 1))
    chain = MipChain(tex)
    i, j = 2, 5
    centre = np.array([(j + 0.5) / 8, (i + 0.5) / 8])
    assert chain.lookup(centre, 0.0)[0] == pytest.approx(tex[i, j, 0])
    # halfway between two texel centres: their mean; across the wrap-around seam as well
    mid = np.array([(j + 1) / 8, (i + 0.5) / 8])
    assert chain.lookup(mid, 0.0)[0] == pytest.approx(0.5 * (tex[i, j, 0] + tex[i, j + 1, 0]))
    seam = np.array([0.0, (i + 0.5) / 8])
    assert chain.lookup(seam, 0.0)[0] == pytest.approx(0.5 * (tex[i, 0, 0] + tex[i, 7, 0]))
    assert chain.lookup(seam + 1.0, 0.0)[0] == pytest.approx(chain.lookup(seam, 0.0)[0])
    # lod between levels: linear blend of the two levels' values at a level-1 texel centre
    c1 = np.array([(1 + 0.5) / 4, (2 + 0.5) / 4])
    v0 = chain.lookup(c1, 0.0)[0]
    v1 = chain.levels[1][2, 1, 0]
    assert chain.lookup(c1, 1.0)[0] == pytest.approx(v1)
    assert chain.lookup(c1, 0.25)[0] == pytest.approx(0.75 * v0 + 0.25 * v1)
    assert chain.lookup(c1, 99.0)[0] == pytest.approx(tex.mean())
    # batch shapes broadcast
    uv = rng.uniform(size=(3, 4, 2))
    assert chain.lookup(uv, np.zeros((3, 4))).shape == (3, 4, 1)


def test_footprint_axes_match_svd():
    rng = np.random.default_rng(4)
    j = rng.normal(size=(50, 2, 2)) * 0.01
    major, minor, d = footprint_axes(j, (64, 128))
    jt = j * np.array([128.0, 64.0])[:, None]
    u, s, _ = np.linalg.svd(jt)
    assert np.allclose(major, s[:, 0]) and np.allclose(minor, s[:, 1])
    assert np.allclose(np.abs(np.sum(d * u[:, :, 0], -1)), 1.0)


def test_lod_from_footprint():
    j = np.diag([4.0 / 32, 2.0 / 32])  # 4 x 2 texels on a 32 x 32 texture
    assert lod_from_footprint(j, (32, 32)) == pytest.approx(2.0)
    assert lod_from_footprint(j, (32, 32), anisotropic=True) == pytest.approx(1.0)
    assert lod_from_footprint(j * 0.1, (32, 32)) == 0.0  # magnification clamps to level 0
    with pytest.raises(PrefilterError, match="dudv"):
        lod_from_footprint(np.zeros(3), (32, 32))


def test_anisotropic_keeps_detail_across_the_minor_axis():
    n = 32
    stripes = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)[None, :, None] * np.ones((n, 1, 1))
    chain = MipChain(stripes)
    uv = np.array([(4 + 0.5) / n, 0.5])
    along_y = np.diag([1.0 / n, 8.0 / n])  # footprint 1 texel wide in x, 8 long in y
    along_x = np.diag([8.0 / n, 1.0 / n])
    assert chain.lookup_footprint(uv, along_y)[0] == pytest.approx(0.0, abs=1e-12)  # blurred
    assert chain.lookup_footprint(uv, along_y, anisotropic=True)[0] == pytest.approx(1.0)
    assert chain.lookup_footprint(uv, along_x, anisotropic=True)[0] == pytest.approx(0.0, abs=1e-12)


def test_moments_give_block_mean_and_covariance():
    s = height_map("anisotropic", 64, 2, cov=[[0.05, 0.01], [0.01, 0.02]], corr_length=3.0).slopes
    chain = moment_chain(s)
    mean, cov = moments_to_stats(chain.levels[2])
    blocks = s.reshape(16, 4, 16, 4, 2).transpose(0, 2, 1, 3, 4).reshape(16, 16, 16, 2)
    bm = blocks.mean(2)
    d = blocks - bm[:, :, None]
    bc = np.einsum("abki,abkj->abij", d, d) / 16
    assert np.allclose(mean, bm) and np.allclose(cov, bc)
    h = height_map("gaussian", 32, 0).height
    m, v = moments_to_stats(moment_chain(h).levels[-1][0, 0])
    assert m == pytest.approx(h.mean()) and v == pytest.approx(h.var())


def test_bad_inputs():
    with pytest.raises(PrefilterError, match="power-of-two"):
        MipChain(np.zeros((6, 8)))
    with pytest.raises(PrefilterError, match="uv"):
        MipChain(np.zeros((4, 4))).lookup(np.zeros(3))
    with pytest.raises(PrefilterError, match="data"):
        moment_chain(np.zeros((4, 4, 3)))
