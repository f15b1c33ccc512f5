"""Range queries over the implicit Wang tiling (``wang_range.ndf_ranges``): rectangle means of
the footprint NDF against the per-footprint NumPy image (``wang_ndf.ndf_image``) in the per-tile,
tile-type-shares and expected-tiling regimes, across tile borders; nothing below min_sigma."""

from dataclasses import replace

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints.wang import index_map, synthesize
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
