"""Wang tiles (glints paper sec. 5.5): edge-colour consistency of the implicit tiling, seamless
tile edges, implicit == explicit (stored index map) P-NDFs (the paper's Fig. 14), constant
storage; per-tile pyramids against the direct P-NDF across tiles, tile shares of the footprint
mass, sampling (pdf == eval, chi-square)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from maps import gaussian_heightfield, sinusoid
from scipy.stats import chi2

from prefilter.errors import PrefilterError
from prefilter.glints.pndf import SIGMA_H, TRUNCATION
from prefilter.glints.wang import (assemble, index_map, pndf_explicit, pndf_image_implicit,
                                   pndf_implicit, synthesize, tile_index)
from prefilter.glints.wang_ndf import (MOMENT_PAIRS, TiledNDF, bake_tiles, compress_tiles,
                                       contributions, moment_basis, ndf, ndf_image, ndf_pdf,
                                       ndf_points, sample, tile_moment_images, type_moments,
                                       type_shares, vertex_config, vertex_elements)

T = 16


@pytest.fixture(scope="module")
def wt():
    return synthesize(sinusoid(64, ax=0.25, ay=0.2, px=16, py=8), tile=T, band=3.0, rng=4)


def test_edge_colours_match(wt):
    idx = index_map(wt, 40, 50, -20, 7)
    n, s, w, e = idx & 1, (idx >> 1) & 1, (idx >> 2) & 1, (idx >> 3) & 1
    np.testing.assert_array_equal(s[:-1], n[1:])  # tile below shares the horizontal edge
    np.testing.assert_array_equal(e[:, :-1], w[:, 1:])  # tile to the right, the vertical one
    counts = np.bincount(idx.ravel(), minlength=16)
    assert np.all(counts > 0.5 * idx.size / 16)  # all 16 tiles, roughly uniformly


def test_tile_edges_are_seamless(wt):
    """Across tile edges (away from the corner squares) neighbouring texels are as close as
    neighbours of the smooth input; across a wrong patch they would jump."""
    big = assemble(wt, index_map(wt, 6, 6))
    s = big[..., :2]
    mid = slice(4, T - 4)
    d_edges = []
    for k in range(1, 6):
        rows = s[k * T - 1:k * T + 1].reshape(2, 6, T, 2)[:, :, mid]
        cols = s[:, k * T - 1:k * T + 1].reshape(6, T, 2, 2)[:, mid]
        d_edges += [np.abs(rows[1] - rows[0]).max(), np.abs(cols[:, :, 1] - cols[:, :, 0]).max()]
    src = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)[..., :2]
    d_src = max(np.abs(np.diff(src, axis=0)).max(), np.abs(np.diff(src, axis=1)).max())
    assert max(d_edges) <= d_src + 1e-12
    # the synthesised map differs from any single patch: tiles really mix four sources
    assert np.abs(np.diff(s, axis=0)).max() > d_src


@pytest.mark.parametrize("c, sp", [((37.3, 52.1), 3.0), ((48.0, 40.0), 9.0), ((60.2, 71.4), 6.0)])
def test_implicit_equals_explicit(wt, c, sp):
    idx = index_map(wt, 8, 8)
    g = np.linspace(-0.35, 0.35, 41)
    s = np.stack(np.meshgrid(g, g), -1)
    a = pndf_implicit(wt, c, sp, s, 0.01)
    b = pndf_explicit(wt, idx, c, sp, s, 0.01)
    assert b.max() > 1.0
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * b.max())


def test_constant_storage(wt):
    before = wt.nbytes
    g = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 9), np.linspace(-0.3, 0.3, 9)), -1)
    for c in ((10.0, 10.0), (1e6 + 0.3, -3e5), (-7e7, 2e7)):
        v = pndf_implicit(wt, c, 5.0, g, 0.02)
        assert np.all(np.isfinite(v)) and v.sum() > 0
    assert wt.nbytes == before == 16 * T * T * 3 * 8
    assert tile_index(wt, 10**9, -(10**9)).shape == ()


def test_validation():
    nm = sinusoid(32)
    with pytest.raises(PrefilterError, match="tile"):
        synthesize(nm, tile=15)
    with pytest.raises(PrefilterError, match="band"):
        synthesize(nm, tile=16, band=20)


# ---------------------------------------------------------------------------------------------
# per-tile pyramids

R, SUPPORT, SR = 32, 0.5, 0.01


@pytest.fixture(scope="module")
def wn(wt):
    return bake_tiles(wt, ndf_res=R, support=SUPPORT, intrinsic_roughness=SR)


def _rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("c, sp", [
    ((8.3, 7.9), 3.0),     # inside one tile
    ((15.7, 40.2), 3.0),   # straddling a vertical edge
    ((16.2, 31.9), 3.0),   # on a corner (four tiles, the dependent texels of each)
    ((47.6, 33.1), 4.6),   # between levels 1 and 2
    ((40.3, 45.2), 7.9),   # just below the switch: ~40 tiles' contributions
    ((-100.4, 70.7), 2.6),  # negative coordinates, near level 0
])
def test_tiled_matches_direct(wn, wt, c, sp):
    """Sum of per-tile contributions == the direct P-NDF of the assembled texels."""
    ij, imgs = contributions(wn, c, sp)
    assert len(ij) > 0  # the per-tile path, not a fallback
    b = pndf_image_implicit(wt, c, sp, R, SUPPORT, SR)
    assert _rel(imgs.sum(axis=0), b) < 1.5e-3  # float32 storage, resampling aliasing


def test_direct_fallback_below_min_sigma(wn, wt):
    c = (21.3, 9.8)
    assert wn.min_sigma > wn.sigma0
    for sp in (0.0, 1.0, 0.99 * wn.min_sigma):
        ij, imgs = contributions(wn, c, sp)
        assert len(ij) == 0
        np.testing.assert_allclose(imgs[0], pndf_image_implicit(wt, c, sp, R, SUPPORT, SR),
                                   rtol=1e-12, atol=1e-12)


def test_vertex_elements_fix_the_dependent_texels(wn, wt):
    """Every valid 2 x 2 block of tiles (4096: 16 x 8 x 8 x 4) gives the dependent texels at
    its centre vertex the slopes and central-difference Jacobians of the table row of its
    vertex configuration (the four edge colours there decide them), and the 16 rows differ."""
    tab = vertex_elements(wn)
    S = wt.tiles[..., :2]
    n, s, w, e = (np.arange(16) >> b & 1 for b in range(4))
    blocks = 0
    for tl in range(16):
        for tr in np.flatnonzero(w == e[tl]):
            for bl in np.flatnonzero(n == s[tl]):
                for br in np.flatnonzero((w == e[bl]) & (n == s[tr])):
                    B = np.concatenate([np.concatenate([S[tl], S[tr]], 1),
                                        np.concatenate([S[bl], S[br]], 1)], 0)
                    row = tab[vertex_config(tl, br)]
                    x = row[:, 0].astype(int) + T
                    y = row[:, 1].astype(int) + T
                    jx = 0.5 * (B[y, x + 1] - B[y, x - 1])
                    jy = 0.5 * (B[y + 1, x] - B[y - 1, x])
                    want = np.column_stack([B[y, x], jx[:, 0], jy[:, 0], jx[:, 1], jy[:, 1]])
                    np.testing.assert_array_equal(row[:, 2:], want)
                    blocks += 1
    assert blocks == 4096 and len(tab[0]) == len(wn.dependent) > 0
    assert len({r.tobytes() for r in tab}) == 16


def test_tile_shares_of_the_footprint_mass(wn):
    """Each tile's contribution carries its share of the Gaussian footprint weights (closed form:
    separable sums over the texels of the tile in the truncation window)."""
    c, sp = np.array([16.4, 31.7]), 3.7
    ij, imgs = contributions(wn, c, sp)
    h2 = (2 * SUPPORT / R) ** 2
    tot2 = sp * sp + SIGMA_H**2
    rad = TRUNCATION * math.sqrt(tot2)
    axes = []
    for a in (0, 1):
        x = np.arange(math.ceil(c[a] - rad - 0.5), math.floor(c[a] + rad - 0.5) + 1)
        axes.append((x // 16, np.exp(-(c[a] - x - 0.5) ** 2 / (2 * tot2))))
    total = axes[0][1].sum() * axes[1][1].sum()
    big = 0
    for (i, j), img in zip(ij, imgs):
        share = (axes[0][1][axes[0][0] == i].sum() * axes[1][1][axes[1][0] == j].sum() / total)
        assert img.sum() * h2 == pytest.approx(share, abs=2e-4)
        big += share > 0.1
    assert big == 4


def test_implicit_equals_explicit_tiled(wn, wt):
    """The paper's Fig. 14 on the precomputed path: a stored index map gives the same NDFs."""
    idx = index_map(wt, 8, 8)
    for c, sp in (((37.3, 52.1), 3.0), ((48.0, 40.0), 6.0), ((60.2, 71.4), 1.5),
                  ((60.0, 61.0), 9.0)):
        a = ndf_image(wn, c, sp)
        b = ndf_image(wn, c, sp, index=idx)
        assert a.max() > 1.0
        np.testing.assert_array_equal(a, b)


def test_point_values_match_direct_image(wn, wt):
    c, sp = (31.6, 16.3), 5.0
    direct = pndf_image_implicit(wt, c, sp, R, SUPPORT, SR)
    g = np.linspace(-SUPPORT, SUPPORT, R, endpoint=False) + SUPPORT / R  # pixel centres
    s = np.stack(np.meshgrid(g, g), -1)
    v = ndf(wn, c, sp, s)
    np.testing.assert_allclose(v, direct, rtol=0, atol=1.5e-3 * direct.max())
    assert ndf(wn, c, sp, [0.6, 0.0]) == 0.0  # outside the support


def test_wide_footprints_use_the_expected_tiling(wn, wt):
    """Above the switch the NDF is the position average over the tiled plane, which is the same
    at every footprint size (Monte Carlo over random centres of the direct P-NDF at half the
    switch size: agreement within 3 standard errors + the dependent texels' expected-Jacobian
    bias)."""
    assert wn.uniform_sigma == 8 * wn.wang.size
    sp = wn.uniform_sigma
    rng = np.random.default_rng(5)
    cs = rng.uniform(-1e4, 1e4, (24, 2))
    direct = np.array([pndf_image_implicit(wt, c, 6.0, R, SUPPORT, SR) for c in cs])
    avg = direct.mean(axis=0)
    se = np.sqrt(direct.var(axis=0, ddof=1).sum() / len(cs))
    img = ndf_image(wn, (3.0, 4.0), sp)
    np.testing.assert_array_equal(img, wn.mean)
    assert np.linalg.norm(img - avg) < 3 * se + 0.02 * np.linalg.norm(avg)
    assert img.sum() * (2 * SUPPORT / R) ** 2 == pytest.approx(1.0, abs=1e-3)


def test_type_shares_regime(wn, wt):
    """Between the switches: the footprint's Gaussian weights over the assembled texels times
    polynomials of each texel's place in its tile (``moment_basis``), summed by tile type
    (``type_moments``, closed form here; column 0 the plain shares), weight the tiles' moment
    images; the error vs the direct P-NDF falls with the footprint and is far below the plain
    shares' (measured at T/2 and T on this map: 3.0 / 1.4 % with the moments, 11.5 / 2.9 %
    with the shares alone)."""
    c, sp = np.array([-37.3, 18.9]), 16.0
    idx = index_map(wt, 12, 12, -8, -5)  # tiles i -8..3, j -5..6 cover the window
    tot2 = sp * sp + SIGMA_H**2
    rad = TRUNCATION * math.sqrt(tot2)
    x = np.arange(math.ceil(c[0] - rad - 0.5), math.floor(c[0] + rad - 0.5) + 1)
    y = np.arange(math.ceil(c[1] - rad - 0.5), math.floor(c[1] + rad - 0.5) + 1)
    X, Y = np.meshgrid(x, y)
    w = np.exp(-((c[0] - X - 0.5) ** 2 + (c[1] - Y - 0.5) ** 2) / (2 * tot2))
    types = idx[Y // 16 + 5, X // 16 + 8]
    P = moment_basis(T)
    np.testing.assert_allclose(P @ P.T / T, np.eye(3), atol=1e-12)
    pairs = ((0, 0),) + MOMENT_PAIRS
    expected = np.stack([np.bincount(types.ravel(), weights=(w * P[dy][Y % T] * P[dx][X % T])
                                     .ravel(), minlength=16) for dy, dx in pairs], -1) / w.sum()
    mom = type_moments(wn, c, sp)
    np.testing.assert_allclose(mom, expected, rtol=1e-10, atol=1e-13)
    np.testing.assert_array_equal(type_shares(wn, c, sp), mom[:, 0])
    ij, imgs = contributions(wn, c, sp)
    assert len(ij) == 0 and imgs.shape == (1, R, R)
    E = tile_moment_images(wt, R, SUPPORT, SR, pairs)
    np.testing.assert_allclose(E[:, 0], wn.tile_means, rtol=1e-12, atol=1e-12)
    img = ndf_image(wn, c, sp)
    np.testing.assert_allclose(img, np.maximum(np.einsum("tk,tkij->ij", mom, E), 0),
                               atol=1e-5 * img.max())
    plain = replace(wn, moment_sat=None)
    np.testing.assert_allclose(ndf_image(plain, c, sp),
                               np.einsum("t,tij->ij", mom[:, 0], wn.tile_means), rtol=1e-12)
    for s_p, bound, ratio in ((8.0, 0.05, 0.4), (sp, 0.025, 0.7)):
        d = pndf_image_implicit(wt, c, s_p, R, SUPPORT, SR)
        err, err_plain = _rel(ndf_image(wn, c, s_p), d), _rel(ndf_image(plain, c, s_p), d)
        assert err < bound and err < ratio * err_plain
    g = np.linspace(-SUPPORT, SUPPORT, R, endpoint=False) + SUPPORT / R
    np.testing.assert_allclose(ndf(wn, c, sp, np.stack(np.meshgrid(g, g), -1)), img, rtol=1e-12)


def test_batched_points_match_per_footprint(wn, wt):
    """The Numba batch (all regimes in one kernel) gives what the per-footprint queries give,
    for the implicit and an explicit tiling."""
    rng = np.random.default_rng(8)
    n_f, n_s = 14, 40
    sp = np.exp(rng.uniform(np.log(0.8), np.log(150.0), n_f))
    sp[:4] = [1.7, 3.1, 6.2, 11.0]  # one per regime below the expected tiling, at least
    c = rng.uniform(40.0, 120.0, (n_f, 2))
    s = rng.uniform(-0.55, 0.55, (n_f, n_s, 2))
    idx = index_map(wt, 12, 12)
    for index in (None, idx):
        got = ndf_points(wn, c[:, None], sp[:, None], s, index=index)
        for k in range(n_f):
            if index is not None and sp[k] > 9.0:
                continue  # the explicit map is periodic: wide footprints would wrap onto it
            want = ndf(wn, c[k], sp[k], s[k], index=index)
            np.testing.assert_allclose(got[k], want, rtol=1e-9, atol=1e-9 * want.max())
        assert np.all(got[:, :] >= 0) and got.max() > 1.0


def test_sampling_pdf_equals_eval_and_chi2(wn):
    c, sp, n = (16.2, 31.9), 3.3, 40000
    s, pdf = sample(wn, c, sp, n, rng=11)
    np.testing.assert_allclose(pdf, ndf_pdf(wn, c, sp, s), rtol=1e-12)
    img = ndf_image(wn, c, sp)
    h = 2 * SUPPORT / R
    expected = n * img.ravel() / img.sum()
    ix = np.floor((s[:, 0] + SUPPORT) / h).astype(int)
    iy = np.floor((s[:, 1] + SUPPORT) / h).astype(int)
    observed = np.bincount(iy * R + ix, minlength=R * R)
    assert observed[expected == 0].sum() == 0
    big = expected >= 5
    obs = np.append(observed[big], observed[~big].sum())
    exp = np.append(expected[big], expected[~big].sum())
    stat = ((obs - exp) ** 2 / exp).sum()
    assert chi2.sf(stat, len(obs) - 1) > 1e-3
    s2, pdf2 = sample(wn, c, sp, n, rng=11)
    assert s2.tobytes() == s.tobytes() and pdf2.tobytes() == pdf.tobytes()
    for sp_other in (1.5, 20.0, 200.0):  # direct, tile-type shares, expected tiling
        s3, pdf3 = sample(wn, c, sp_other, 500, rng=2)
        np.testing.assert_allclose(pdf3, ndf_pdf(wn, c, sp_other, s3), rtol=1e-12)
        assert np.all(pdf3 > 0)


def test_tiled_constant_storage(wn):
    """``nbytes`` counts every array the queries read, the range queries' summed-area tables
    from their first use on, and does not grow with the queried area."""
    from prefilter.glints.wang_range import summed_tables

    sat = summed_tables(wn)  # what a range query builds (cached on the instance)
    before = wn.nbytes
    T = wn.wang.size
    per_tile = sum(a[0].nbytes for a in wn.images)
    assert before == (wn.wang.nbytes + 16 * per_tile + wn.mean.nbytes + wn.tile_means.nbytes
                      + wn.means_px.nbytes + wn.moment_sat.nbytes + sat.nbytes)
    assert sat.nbytes == (R + 1) ** 2 * 17 * 8
    for c in ((10.0, 10.0), (1e6 + 0.3, -3e5), (-7e7, 2e7)):
        img = ndf_image(wn, c, 3.0)
        assert np.all(np.isfinite(img))
        assert img.sum() * (2 * SUPPORT / R) ** 2 == pytest.approx(1.0, abs=2e-3)
    assert wn.nbytes == before
    assert isinstance(wn, TiledNDF) and T == 16


def test_tiled_validation(wn, wt):
    with pytest.raises(PrefilterError, match="index"):
        ndf_image(wn, (1.0, 2.0), 3.0, index=np.full((2, 2), 16))
    with pytest.raises(PrefilterError, match="sigma_p"):
        ndf_image(wn, (1.0, 2.0), [3.0, 4.0])
    with pytest.raises(PrefilterError, match="sigma_p"):
        pndf_image_implicit(wt, (1.0, 2.0), [3.0, 4.0])
    with pytest.raises(PrefilterError, match="center"):
        ndf(wn, (1.0, 2.0, 3.0), 3.0, [0.0, 0.0])
    with pytest.raises(PrefilterError, match="wn"):
        sample(wt, (1.0, 2.0), 3.0, 10)
    with pytest.raises(PrefilterError, match="wide_tiles"):
        bake_tiles(wt, wide_tiles=0.0)
    with pytest.raises(PrefilterError, match="uniform_tiles"):
        bake_tiles(wt, wide_tiles=1.0, uniform_tiles=0.5)
    with pytest.raises(PrefilterError, match="stride0"):
        bake_tiles(wt, stride0=0)
    for bad in (-1, 2.5, True):
        with pytest.raises(PrefilterError, match="angular_pool: expected an integer >= 0"):
            bake_tiles(wt, rank=2, angular_pool=bad)


def test_compressed_tiles(wn):
    """CP per (tile, level, block): the stored bytes follow the factor shapes, point values are
    the compressed image's pixels, the queried NDFs are as close to the uncompressed ones as the
    stored images are (relative L2 over several footprints), sampling's pdf == eval."""
    rank, B = 4, 8
    wc = compress_tiles(wn, rank, B, n_iter_max=10)
    nb = R // B
    # packed for the kernels: the live groups' factors and prefix sums, the kept code rows, the
    # row index per (image, block) and the group records
    pk = wc.pack
    live = sum(int((wc.images[lv][2].max(axis=-1) > 0).any(axis=(1, 2)).sum())
               for lv in range(wc.n_levels))
    kept = sum(int((wc.images[lv][2].max(axis=-1) > 0).sum()) for lv in range(wc.n_levels))
    images = sum(16 * wc.crop(lv) ** 2 for lv in range(wc.n_levels))
    expect = (4 * live * rank * (2 * B + 2 * (B + 1) + 1) + 4 * kept * rank
              + 2 * images * nb * nb + 8 * 4 * 16 * nb * nb * wc.n_levels
              + 8 * (3 * wc.n_levels + 2))
    assert pk.nbytes == expect
    assert wc.nbytes == (wn.wang.nbytes + pk.nbytes + wn.mean.nbytes + wn.tile_means.nbytes
                         + wn.means_px.nbytes + wn.moment_sat.nbytes)
    assert wc.nbytes < wn.nbytes / 5
    assert all(0.0 < e < 0.5 for e in wc.cp_error)
    g = np.linspace(-SUPPORT, SUPPORT, R, endpoint=False) + SUPPORT / R
    s = np.stack(np.meshgrid(g, g), -1)
    num = den = 0.0
    for c, sp in (((8.3, 7.9), 3.0), ((16.2, 31.9), 3.0), ((40.3, 45.2), 5.5),
                  ((47.6, 33.1), 4.6), ((-20.1, 3.3), 7.0)):
        a = ndf_image(wc, c, sp)
        np.testing.assert_allclose(ndf(wc, c, sp, s), a, rtol=1e-10, atol=1e-12 * a.max())
        b = ndf_image(wn, c, sp)
        num += np.sum((a - b) ** 2)
        den += np.sum(b * b)
    assert math.sqrt(num / den) < 1.5 * max(wc.cp_error)
    s2, pdf = sample(wc, (16.2, 31.9), 3.0, 2000, rng=3)
    np.testing.assert_allclose(pdf, ndf_pdf(wc, (16.2, 31.9), 3.0, s2), rtol=1e-12)


@pytest.mark.slow
def test_tiled_matches_direct_heightfield_32():
    """Tile 32, NDF 64^2, a Gaussian random heightfield: errors of the per-tile path, of the
    tile-independent switch and of rank-16 compression vs the direct P-NDF (measured numbers in
    docs/glints-wang.md; bounds ~2x those)."""
    nm, _ = gaussian_heightfield(128, corr=3.0, slope_std=0.15, seed=2)
    wt = synthesize(nm, tile=32, band=4.0, rng=1)
    wn = bake_tiles(wt, ndf_res=64, support=0.5, intrinsic_roughness=0.01, wide_tiles=0.5)
    wc = compress_tiles(wn, 16, 16)
    rng = np.random.default_rng(0)
    errs, cerrs = {}, {}
    for sp in (5.5, 9.0, 14.0):
        for c in rng.uniform(-500, 500, (4, 2)):
            d = pndf_image_implicit(wt, c, sp, 64, 0.5, 0.01)
            errs.setdefault(sp, []).append(_rel(ndf_image(wn, c, sp), d))
            cerrs.setdefault(sp, []).append(_rel(ndf_image(wc, c, sp), d))
    assert max(max(e) for e in errs.values()) < 2e-3
    assert np.median(cerrs[5.5]) < 0.2 and np.median(cerrs[14.0]) < 0.06
    cs = rng.uniform(-500, 500, (4, 2))
    shares = [_rel(ndf_image(wn, c, 32.0), pndf_image_implicit(wt, c, 32.0, 64, 0.5, 0.01))
              for c in cs]
    uniform = [_rel(wn.mean, pndf_image_implicit(wt, c, 32.0, 64, 0.5, 0.01)) for c in cs]
    assert max(shares) < 0.08 and max(uniform) < 0.15
