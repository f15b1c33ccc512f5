"""Range queries over the implicit Wang tiling (``wang_range.ndf_ranges``): rectangle means of
the footprint NDF against the per-footprint NumPy image (``wang_ndf.ndf_image``) in the per-tile,
tile-type-shares and expected-tiling regimes, across tile borders; nothing below min_sigma."""

from dataclasses import replace

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints.wang import index_map, is_valid_tiling, periodic_index_map, synthesize
from prefilter.glints.wang_ndf import (bake_tiles, dependent_texels, ndf_image, ndf_points,
                                      vertex_elements, vertex_tiles)
from prefilter.glints.wang_range import ndf_ranges

R, SUPPORT = 16, 0.5


@pytest.fixture(scope="module")
def wc():
    wt = synthesize(sinusoid(32, ax=0.25, ay=0.2, px=16, py=8), tile=8, band=2.0, rng=4)
    return bake_tiles(wt, ndf_res=R, support=SUPPORT, intrinsic_roughness=0.05,
                      uniform_tiles=4, rank=4, block=8, n_iter_max=30)


def _rects(rng, n, k):
    """Pixel-aligned rectangles ``(n, k, 2)`` of 1-6 pixels per side inside the support, and
    their pixel index ranges."""
    h = 2 * SUPPORT / R
    p0 = rng.integers(0, R - 6, (n, k, 2))
    ext = rng.integers(1, 7, (n, k, 2))
    return -SUPPORT + h * p0, -SUPPORT + h * (p0 + ext), p0, ext


def _means(img, p0, ext):
    return np.array([img[p0[k, 1]:p0[k, 1] + ext[k, 1], p0[k, 0]:p0[k, 0] + ext[k, 0]].mean()
                     for k in range(len(p0))])


@pytest.mark.parametrize("vertex", [False, True])
def test_ranges_match_image_means(wc, vertex):
    """Per-tile regime: the image means to float32 rounding (the dependent texels' masses over
    the rectangles as the image splats them; ``vertex``: from the vertex pyramids on the
    implicit tiling, within their CP error: rank 4 fits to 4.7 % / 2.0 % at levels 0 / 1, the
    means to 1.3 % at most); shares and expected tiling: exact; the rectangles of a footprint
    on a tile corner read every tile under it; an explicit index map too (exact dependent
    texels: its tiling need not be valid)."""
    tol = 3e-2 if vertex else 1e-3
    if not vertex:
        wc = replace(wc, vertex_images=(), vertex_cp_error=())
    rng = np.random.default_rng(3)
    T = wc.wang.size
    sig = [1.3 * wc.min_sigma, 0.9 * wc.wide_sigma, 1.5 * wc.wide_sigma, 1.5 * wc.uniform_sigma]
    c = np.array([[T * 3.0 + 0.2, T * 5.0 - 0.3], [17.3, -41.2], [3.3, 2.9], [-90.0, 11.0]])
    for index in (None, index_map(wc.wang, 6, 6)):
        for sp in sig:
            lo, hi, p0, ext = _rects(rng, len(c), 5)
            got, done = ndf_ranges(wc, c, np.full(len(c), sp), lo, hi, index=index)
            assert done.all()
            for q in range(len(c)):
                want = _means(ndf_image(wc, c[q], sp, index=index), p0[q], ext[q])
                if sp < wc.wide_sigma:
                    err = np.abs(got[q] - want).max() / want.max()
                    rel = np.linalg.norm(got[q] - want) / np.linalg.norm(want)
                    bound = tol if index is None else 1e-3
                    assert err < bound and rel < bound, (sp, err, rel)
                else:
                    np.testing.assert_allclose(got[q], want, rtol=1e-9, atol=1e-12)
    # the tile-type shares without the in-tile moments: the plain shares' image means
    plain = replace(wc, moment_sat=None)
    sp = 1.5 * wc.wide_sigma
    lo, hi, p0, ext = _rects(rng, len(c), 5)
    got, _ = ndf_ranges(plain, c, np.full(len(c), sp), lo, hi)
    with_m, _ = ndf_ranges(wc, c, np.full(len(c), sp), lo, hi)
    for q in range(len(c)):
        want = _means(ndf_image(plain, c[q], sp), p0[q], ext[q])
        np.testing.assert_allclose(got[q], want, rtol=1e-9, atol=1e-12)
    assert np.abs(with_m - got).max() > 1e-3 * np.abs(got).max()


def test_ranges_below_min_sigma_and_inactive(wc):
    rng = np.random.default_rng(1)
    lo, hi, _, _ = _rects(rng, 3, 2)
    sp = np.array([0.5 * wc.min_sigma, 1.5 * wc.min_sigma, 2.0 * wc.wide_sigma])
    c = rng.uniform(-50, 50, (3, 2))
    act = np.array([[True, True], [False, True], [True, False]])
    got, done = ndf_ranges(wc, c, sp, lo, hi, active=act)
    assert list(done) == [False, True, True]
    assert np.all(got[0] == 0) and got[1, 0] == 0 and got[2, 1] == 0
    assert got[1, 1] >= 0 and got[2, 0] > 0
    with pytest.raises(PrefilterError, match="s_max"):
        ndf_ranges(wc, c, sp, hi, lo)
    with pytest.raises(PrefilterError, match="compressed"):
        ndf_ranges(bake_tiles(wc.wang, ndf_res=R, support=SUPPORT), c, sp, lo, hi)


def test_vertex_tiles_and_point_queries(wc):
    """The vertex tiles hold each dependent texel of a vertex once, at ``T/2`` plus its offset
    from the vertex (``vertex_elements``' rows); in the per-tile regime on the implicit tiling
    the point queries' pixel values (not ``bilinear``: that takes the exact point densities)
    read the dependent texels from the vertex pyramids, within their CP error (rank 4: 4.7 % /
    2.0 % at levels 0 / 1) of the exact elements' pixel integrals."""
    T = wc.wang.size
    dep = dependent_texels(wc.wang)
    s, J, keep = vertex_tiles(wc.wang, dep)
    rows = vertex_elements(wc)
    assert keep.sum(axis=(1, 2)).tolist() == [dep.sum()] * 16
    for k in range(16):
        y = T // 2 + rows[k, :, 1].astype(int)
        x = T // 2 + rows[k, :, 0].astype(int)
        np.testing.assert_array_equal(s[k, y, x], rows[k, :, 2:4])
        np.testing.assert_array_equal(J[k, y, x].reshape(-1, 4), rows[k, :, 4:])
    rng = np.random.default_rng(7)
    c = rng.uniform(-40, 40, (500, 2))
    sp = rng.uniform(wc.min_sigma, wc.wide_sigma, 500)
    q = rng.uniform(-0.4, 0.4, (500, 2))
    got = ndf_points(wc, c, sp, q)
    exact = ndf_points(replace(wc, vertex_images=()), c, sp, q)
    assert np.linalg.norm(got - exact) / np.linalg.norm(exact) < 2e-2
    # the configurations' pyramids swapped round: far off (what reading the wrong vertex
    # configuration or tile would cost)
    rolled = tuple(tuple(np.roll(x, 1, axis=0) for x in lv) for lv in wc.vertex_images)
    wrong = ndf_points(replace(wc, vertex_images=rolled), c, sp, q)
    assert np.linalg.norm(wrong - exact) / np.linalg.norm(exact) > 0.1


def test_valid_explicit_maps_read_the_vertex_pyramids(wc):
    """An explicit map that tiles validly across its wrap (``periodic_index_map``) is read as
    the implicit tiling (vertex pyramids and tables), within the vertex pyramids' CP error of
    the exact image means; a wrapped block of the implicit tiling is not valid (exact path)."""
    P = periodic_index_map(6, 6, rng=1)
    assert is_valid_tiling(P) and not is_valid_tiling(index_map(wc.wang, 6, 6))
    rng = np.random.default_rng(8)
    c = rng.uniform(-60, 60, (12, 2))
    sp = rng.uniform(wc.min_sigma, wc.wide_sigma, 12)
    lo, hi, p0, ext = _rects(rng, len(c), 5)
    want = np.array([_means(ndf_image(wc, c[q], sp[q], index=P), p0[q], ext[q])
                     for q in range(len(c))])
    got, _ = ndf_ranges(wc, c, sp, lo, hi, index=P)
    exact, _ = ndf_ranges(replace(wc, vertex_images=()), c, sp, lo, hi, index=P)
    assert np.linalg.norm(exact - want) / np.linalg.norm(want) < 1e-3
    err = np.linalg.norm(got - want) / np.linalg.norm(want)
    assert 1e-4 < err < 3e-2  # the vertex pyramids' error: they were read


@pytest.fixture(scope="module")
def wpool():
    wt = synthesize(sinusoid(32, ax=0.25, ay=0.2, px=16, py=8), tile=8, band=2.0, rng=4)
    return bake_tiles(wt, ndf_res=32, support=SUPPORT, intrinsic_roughness=0.05,
                      uniform_tiles=4, rank=6, block=4, n_iter_max=40, angular_pool=2)


def _covered_means(img, lo, hi):
    """Means of a piecewise-constant image over rectangles ``lo``, ``hi (K, 2)`` with the
    partial pixels they cover (exact)."""
    n = img.shape[0]
    e = np.arange(n + 1)
    out = []
    for a, b in zip(lo, hi):
        p0 = (a + SUPPORT) * n / (2 * SUPPORT)
        p1 = (b + SUPPORT) * n / (2 * SUPPORT)
        wx = np.clip(np.minimum(e[1:], p1[0]) - np.maximum(e[:-1], p0[0]), 0, None)
        wy = np.clip(np.minimum(e[1:], p1[1]) - np.maximum(e[:-1], p0[1]), 0, None)
        out.append((wy[:, None] * wx[None] * img).sum() / np.prod(p1 - p0))
    return np.array(out)


def test_coarse_pyramids_serve_wide_rectangles(wpool, tmp_path):
    """``angular_pool``: rectangles of >= COARSE_MIN coarse pixels per side are read from the
    pyramids of the pooled images (within their CP error, rank 6: 4.6 % / 1.7 % at levels 0 /
    1, and the coarse pixels' coverage of the exact means; 4.2 % measured at 3.8 coarse pixels
    per side), narrower ones from the full-resolution pyramids (the same
    values as without the coarse pyramids); the store keeps them (version 3)."""
    from prefilter.glints.wang_range import COARSE_MIN
    from prefilter.glints.wang_store import load_tiles, save_tiles

    c_ = wpool.coarse
    assert c_ is not None and c_.resolution == 16 and len(c_.vertex_images) == wpool.n_levels
    hc = 2 * SUPPORT / c_.resolution
    rng = np.random.default_rng(2)
    n = 60
    c = rng.uniform(-30, 30, (n, 2))
    sp = rng.uniform(wpool.min_sigma, wpool.wide_sigma, n)
    lo = rng.uniform(-0.5, -0.1, (n, 2, 2))
    wide = np.array([COARSE_MIN * hc + 0.05, 0.8 * COARSE_MIN * hc])[None, :, None]
    assert wide.max() <= 1.0  # one wide, one narrow, inside the support
    hi = lo + wide
    fine = replace(wpool, coarse=None)
    got, _ = ndf_ranges(wpool, c, sp, lo, hi)
    ref, _ = ndf_ranges(fine, c, sp, lo, hi)
    np.testing.assert_array_equal(got[:, 1], ref[:, 1])
    exact = np.array([_covered_means(ndf_image(fine, c[q], sp[q]), lo[q], hi[q])
                      for q in range(n)])
    rel = np.linalg.norm(got[:, 0] - exact[:, 0]) / np.linalg.norm(exact[:, 0])
    assert 1e-4 < rel < 6e-2
    assert np.linalg.norm(ref[:, 0] - exact[:, 0]) / np.linalg.norm(exact[:, 0]) < 1e-3
    save_tiles(wpool, tmp_path / "p.npz")
    back = load_tiles(tmp_path / "p.npz")
    assert back.coarse is not None and back.coarse.resolution == 16
    again, _ = ndf_ranges(back, c, sp, lo, hi)
    assert np.linalg.norm(again - got) / np.linalg.norm(got) < 1e-2
