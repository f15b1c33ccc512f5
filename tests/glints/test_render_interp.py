"""Footprint interpolation over the pyramid: Gaussian resampling against the closed-form footprint
and against the direct P-NDF of the footprint; bilinear NDF lookup against the pixel values."""

import numpy as np
import pytest
from maps import gaussian_heightfield

from prefilter.errors import PrefilterError
from prefilter.glints import load
from prefilter.glints.bake import bake
from prefilter.glints.pndf import pndf
from prefilter.glints.pyramid import (interp_weights, plan, resample_min_sigma,
                                      resample_weights)
from prefilter.glints.query import point, point_weighted, weights


def _centres(pyr, idx):
    """Footprint centres ``(..., 2)`` and stds of flat image indices (from the pyramid's own
    geometry: level ``l`` has stride ``stride0 2^l``, centres at ``k stride + 0.5``)."""
    offs = pyr.offsets
    lv = np.searchsorted(offs, idx, side="right") - 1
    k = idx - offs[lv]
    nx = np.array([pyr.shape(v)[1] for v in range(pyr.n_levels)])[lv]
    st = pyr.stride0 * 2.0 ** lv
    return np.stack([(k % nx) * st + 0.5, (k // nx) * st + 0.5], -1), pyr.sigma0 * 2.0 ** lv


def _periodic_gauss(u, c, sigma, size):
    d = (u - c + size / 2) % size - size / 2
    return np.exp(-0.5 * np.sum(d * d, -1) / sigma**2) / (2 * np.pi * sigma**2)


@pytest.mark.parametrize("sp", [4.6, 5.5, 7.9, 9.3, 13.0, 22.0])
def test_resampled_footprint_is_the_gaussian(sp):
    """sum_k w_k G_{sigma_m}(u - c_k) == G_sigma(u - c) (closed form) within the aliasing and
    truncation bound; the trilinear blend is far from it between the samples."""
    pyr = plan(128, 128, 4)
    rng = np.random.default_rng(1)
    c = rng.uniform(0, 128, (5, 2))
    idx, w, ok = resample_weights(pyr, c, np.full(5, sp))
    assert np.all(ok)
    np.testing.assert_allclose(w.sum(1), 1.0, rtol=1e-12)
    x = np.arange(128) + 0.5
    u = np.stack(np.meshgrid(x, x), -1)
    tidx, tw = interp_weights(pyr, c, np.full(5, sp))
    for q in range(5):
        want = _periodic_gauss(u, c[q], sp, 128)
        cen, sg = _centres(pyr, idx[q])
        got = sum(wk * _periodic_gauss(u, ck, sk, 128)
                  for wk, ck, sk in zip(w[q], cen, sg) if wk > 0)
        err = np.abs(got - want).sum() / want.sum()
        assert err < 0.03, err
        cen, sg = _centres(pyr, tidx[q])
        tri = sum(wk * _periodic_gauss(u, ck, sk, 128) for wk, ck, sk in zip(tw[q], cen, sg))
        if abs(np.log2(sp / 4) - round(np.log2(sp / 4))) > 0.2:
            assert np.abs(tri - want).sum() / want.sum() > 3 * err


def test_resample_range_and_fallback():
    pyr = plan(64, 64, 4)
    sm = resample_min_sigma(pyr)
    assert sm == pytest.approx(4.0 / np.sqrt(1 - 0.45**2))
    c = np.array([[3.0, 7.0]] * 4)
    _, _, ok = resample_weights(pyr, c, np.array([0.98 * sm, 1.02 * sm, 30.0, 1e4]))
    # below: no level resolves the kernel; above the top: converged, clamped trilinear
    np.testing.assert_array_equal(ok, [False, True, True, False])


@pytest.fixture(scope="module")
def rough(tmp_path_factory):
    nm, _ = gaussian_heightfield(32, corr=2.0, slope_std=0.2, seed=3)
    out = tmp_path_factory.mktemp("ri") / "m.npz"
    bake(nm, out, rank=16, ndf_res=64, block=16, support=1.0, cell=16, converge=0.0,
         intrinsic_roughness=0.03, progress=False)
    return nm, load(out)


def test_resampled_ndf_matches_the_direct_pndf(rough):
    """The compressed, resampled NDF against the direct P-NDF of the same footprint (pixel
    averages of ``pndf`` by 4x4 midpoints) between pyramid samples: the compression error, not the
    interpolation's (the trilinear blend is worse)."""
    nm, gm = rough
    rng = np.random.default_rng(5)
    R, S = gm.resolution, gm.support
    h = 2 * S / R
    errs = {"resample": [], "trilinear": []}
    for sp in (5.3, 6.7):
        c = rng.uniform(0, 32, 2)
        x = (np.arange(R) + 0.5) * h - S
        sub = (np.arange(4) + 0.5) / 4 * h - h / 2
        X, Y = np.meshgrid(x, x)
        px = np.broadcast_to(X[..., None, None] + sub[None, None, None, :], (R, R, 4, 4))
        py = np.broadcast_to(Y[..., None, None] + sub[None, None, :, None], (R, R, 4, 4))
        pts = np.stack([px, py], -1)
        ref = pndf(nm, c, sp, pts, 0.03).mean(axis=(2, 3))
        for it in errs:
            got = point(gm, c, sp, np.stack([X, Y], -1), interp=it)
            errs[it].append(np.linalg.norm(got - ref) / np.linalg.norm(ref))
    assert max(errs["resample"]) < 0.02, errs  # measured 0.5 / 0.3 % (trilinear 3.4 / 2.7 %)
    assert np.mean(errs["resample"]) < np.mean(errs["trilinear"]), errs


def test_bilinear_lookup_between_pixel_values(rough):
    """Bilinear lookup == bilinear interpolation of the pixel values (point queries at the pixel
    centres, zero outside the support); equal to them at the centres."""
    _, gm = rough
    rng = np.random.default_rng(6)
    n = 500
    c = rng.uniform(0, 32, (n, 2))
    sp = rng.uniform(4, 30, n)
    h = 2 * gm.support / gm.resolution
    s = rng.uniform(-1, 1, (n, 2))
    g = (s + gm.support) / h - 0.5
    j0 = np.floor(g)
    t = g - j0
    want = 0.0
    for dy in (0, 1):
        for dx in (0, 1):
            jj = j0 + [dx, dy]
            inside = np.all((jj >= 0) & (jj < gm.resolution), 1)
            v = point(gm, c, sp, (jj + 0.5) * h - gm.support)
            wt = (t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1])
            want = want + wt * np.where(inside, v, 0.0)
    got = point(gm, c, sp, s, bilinear=True)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * want.max())
    centres = (np.floor((s + gm.support) / h) + 0.5) * h - gm.support
    np.testing.assert_allclose(point(gm, c, sp, centres, bilinear=True),
                               point(gm, c, sp, centres), rtol=1e-6, atol=1e-12)


def test_batch_api_validation(rough):
    _, gm = rough
    with pytest.raises(PrefilterError, match="interp"):
        weights(gm, np.zeros((2, 2)), np.ones(2), interp="cubic")
    with pytest.raises(PrefilterError, match="center, sigma_p"):
        weights(gm, np.zeros((2, 2)), np.ones(3))
    with pytest.raises(PrefilterError, match="gm"):
        weights(None, np.zeros((2, 2)), np.ones(2))


@pytest.mark.parametrize("bilinear", [False, True])
def test_fused_resampling_equals_the_weighted_blend(rough, bilinear):
    """The fused kernel (taps generated in place, C rows summed per CP group before the factor
    product) equals the explicit tap list of ``resample_weights`` evaluated image by image, for
    footprints whose taps span several cells (cell 16 texels, taps up to 3 r ~ 16 texels out)."""
    _, gm = rough
    rng = np.random.default_rng(8)
    n = 400
    c = rng.uniform(0, 32, (n, 2))
    sp = rng.uniform(4.5, 16.0, n)
    s = rng.normal(0.0, 0.3, (n, 2))
    idx, w, ok = weights(gm, c, sp, interp="resample")
    assert ok.mean() > 0.9
    assert len(np.unique(gm.image_cell[idx[ok & (sp < 8.9)]])) > 1
    want = point_weighted(gm, idx, w, s, bilinear=bilinear)
    got = point(gm, c, sp, s, interp="resample", bilinear=bilinear)
    # float32 factors: the two paths round their products differently (measured 2.5e-8)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())


def test_render_bake_keeps_dim_ndf_blocks(tmp_path, monkeypatch):
    """The render bake (``bake.BAKE_SETTINGS``) keeps NDF blocks whose maximum is 1e-6 to 1e-4
    of their image's maximum: their compressed mass follows the direct pixel averages
    (``pndf_image`` at the bake's roughness). Dropped as blank (the bake's default ``blank_tol``
    1e-4), they were zero, which moved the dim glints of the scratches map (FLIP 0.08 at mid)."""
    import prefilter.glints.render as gr
    from prefilter.glints import pndf_image
    from prefilter.texture.procedural import normal_map

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.setitem(gr.BAKE_SETTINGS, "ndf_res", 64)
    monkeypatch.setitem(gr.BAKE_SETTINGS, "block", 16)  # 16 blocks per image, as measured
    monkeypatch.setitem(gr.BAKE_SETTINGS, "intrinsic_roughness", 0.02)
    monkeypatch.setitem(gr.BAKE_SETTINGS, "rank", 16)
    monkeypatch.setitem(gr.BAKE_SETTINGS, "stride0", 4)  # 64 level-0 images of the 32^2 map
    monkeypatch.setattr(gr, "_SURFACES", {})
    nm = normal_map("flakes", size=32, seed=1)
    gm = gr.baked_surface(nm).gm
    pyr, R = gm.pyramid, gm.resolution
    # the direct images with the bake's cuts (bake.BAKE_SETTINGS)
    cuts = {k: gr.BAKE_SETTINGS[k] for k in ("ndf_truncation", "footprint_truncation")
            if k in gr.BAKE_SETTINGS}
    want = pndf_image(nm, pyr.centers(0), pyr.sigma(0), R, gm.support,
                      gm.header["ndf"]["intrinsic_roughness"], **cuts).reshape(-1, R, R)
    h = 2 * gm.support / R
    x = (np.arange(R) + 0.5) * h - gm.support
    grid = np.stack(np.meshgrid(x, x), -1)
    # trilinear weights at a level-0 centre and sigma0 select that image alone
    got = point(gm, pyr.centers(0).reshape(-1, 1, 1, 2), pyr.sigma(0), grid[None])
    nb = R // gm.block
    wb = want.reshape(-1, nb, gm.block, nb, gm.block)
    gb = got.reshape(wb.shape)
    rel = wb.max(axis=(2, 4)) / want.max(axis=(1, 2))[:, None, None]
    # measured (blank_tol 1e-6, cuts 6 / 6; the footprint cut at 5 moves images by < 1e-6):
    # total mass 0.94 / 0.77, per-block median 0.983 /
    # 0.991 for the 1e-5..1e-4 (126 blocks) / 1e-6..1e-5 (102 blocks) bands (cuts 4 / 4: 0.96 /
    # 0.80, 0.996 / 0.997); dropped blocks give 0. Against 4-std direct images the 6-std bake
    # failed the median (1.067 in the 1e-6 band: the tails the direct image lacked)
    for lo, total in ((1e-5, 0.1), (1e-6, 0.35)):
        dim = (rel > lo) & (rel <= 10 * lo)
        assert dim.sum() >= 50, (lo, dim.sum())
        mg, mw = gb.sum(axis=(2, 4))[dim], wb.sum(axis=(2, 4))[dim]
        assert mg.sum() / mw.sum() == pytest.approx(1.0, abs=total), lo
        assert np.median(mg / mw) == pytest.approx(1.0, abs=0.05), lo


def test_direct_surfaces_of_one_map_at_two_roughnesses_are_distinct():
    """``baked_surface(direct=True)`` keeps one surface per (map, intrinsic roughness): the
    in-memory cache once keyed it by the map alone and returned the first roughness' surface."""
    import prefilter.glints.render as gr
    from prefilter.texture.procedural import normal_map

    nm = normal_map("flakes", size=16, seed=3)
    a = gr.baked_surface(nm, direct=True, settings={"intrinsic_roughness": 0.02})
    b = gr.baked_surface(nm, direct=True, settings={"intrinsic_roughness": 0.03})
    assert (a.intrinsic_roughness, b.intrinsic_roughness) == (0.02, 0.03)
    assert gr.baked_surface(nm, direct=True, settings={"intrinsic_roughness": 0.02}) is a


def test_level0_variant_bakes_level_0_at_its_stride(tmp_path, monkeypatch):
    """``--param level0=4``: the render bakes (and reads) the map with level 0 at 4 texels, the
    default at ``BAKE_SETTINGS["stride0"]`` (8); both shade the scene; other values are
    rejected naming the choices."""
    import prefilter.glints.render as gr
    from prefilter.glints.store import load as load_map
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.setitem(gr.BAKE_SETTINGS, "ndf_res", 64)
    monkeypatch.setitem(gr.BAKE_SETTINGS, "intrinsic_roughness", 0.02)
    monkeypatch.setattr(gr, "_SURFACES", {})
    sc = load_scene(gr.measurement_scene(2.0, "flakes", 32, width=16, height=12))
    a = render(sc, "glints", seed=1)
    b = render(sc, "glints", seed=1, params={"level0": "4"})
    strides = sorted(load_map(p).header["settings"]["stride0"] for p in tmp_path.glob("*.npz"))
    assert strides == [4, gr.BAKE_SETTINGS["stride0"]]
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and a.mean() > 0
    assert b.mean() == pytest.approx(a.mean(), rel=0.1)
    with pytest.raises(PrefilterError, match="level0"):
        render(sc, "glints", params={"level0": "5"})
