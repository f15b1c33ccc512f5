"""The ``glints-wang`` render method (issue #9): the batched point query on compressed per-tile
pyramids against the per-footprint one; the method on an explicit periodic tile index map
against ``glints-direct`` on the assembled normal map (near / mid / far footprints); errors."""

import json

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints import render as grender
from prefilter.glints.bake import settings_key
from prefilter.glints.wang import (assemble, edge_colours, index_map,
                                   periodic_index_map, synthesize)
from prefilter.glints.wang_ndf import bake_tiles, compress_tiles, ndf, ndf_points
from prefilter.glints.wang_render import (baked_tiles, cache_path, render_wang, tile_size,
                                          wang_settings)
from prefilter.render.methods import RenderSettings, available, describe
from prefilter.render.metrics import flip
from prefilter.render.driver import render
from prefilter.render.scene import load_scene
from prefilter.texture.normalmap import encode_normals


@pytest.fixture(scope="module")
def wn_pair():
    wt = synthesize(sinusoid(32, ax=0.25, ay=0.2, px=16, py=8), tile=8, band=2.0, rng=4)
    wn = bake_tiles(wt, ndf_res=16, support=0.5, intrinsic_roughness=0.05, uniform_tiles=4)
    return wn, compress_tiles(wn, 4, 8, n_iter_max=30)


def test_compressed_batched_query_equals_per_footprint(wn_pair):
    """ndf_points on CP-compressed pyramids == ndf (per footprint, numpy) in every regime, with
    the hashing and with an explicit index map; and differs from the uncompressed values by the
    compression error (the compressed path is really taken)."""
    wn, wc = wn_pair
    rng = np.random.default_rng(0)
    n_f, n_s = 48, 6
    c = rng.uniform(-100, 100, (n_f, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(60.0), n_f))
    regimes = np.digitize(sp, [wc.min_sigma, wc.wide_sigma, wc.uniform_sigma])
    assert set(regimes) == {0, 1, 2, 3}
    s = rng.uniform(-0.55, 0.55, (n_f, n_s, 2))
    for index in (None, index_map(wc.wang, 12, 12)):
        got = ndf_points(wc, c[:, None], sp[:, None], s, index=index)
        want = np.stack([ndf(wc, c[k], sp[k], s[k], index=index) for k in range(n_f)])
        # float32 factors: ndf blends them in float32 einsums, the kernel in float64
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
        dense = ndf_points(wn, c[:, None], sp[:, None], s, index=index)
        tiles = regimes == 1
        rel = np.linalg.norm(got[tiles] - dense[tiles]) / np.linalg.norm(dense[tiles])
        assert 1e-4 < rel < 0.3, rel
        np.testing.assert_array_equal(got[~tiles], dense[~tiles])  # no pyramid used there


def test_periodic_index_map_is_a_wang_tiling():
    """Edge colours match between neighbours, across the wrap too (index_map's blocks do not)."""
    idx = periodic_index_map(5, 7, rng=2)
    big = np.tile(idx, (2, 2))
    n, s, w, e = edge_colours(big)
    np.testing.assert_array_equal(s[:-1], n[1:])
    np.testing.assert_array_equal(e[:, :-1], w[:, 1:])
    assert len(np.unique(idx)) > 8
    n, s, w, e = edge_colours(np.tile(index_map(synthesize(sinusoid(8), 4, 1.0), 5, 7), (2, 2)))
    assert np.any(s[:-1] != n[1:]) or np.any(e[:, :-1] != w[:, 1:])


def _scene(nm_file, d, size, width=32, height=24):
    sc = grender.measurement_scene(d, size=size, width=width, height=height)
    sc["objects"][0]["material"]["normal_map"] = str(nm_file)
    return load_scene(sc)


def _assembled_vs_direct(tmp_path, monkeypatch, exemplar, wang, sr, distances, ny):
    """FLIP and mean ratio of glints-wang (explicit ny x ny index map) against glints-direct on
    the assembled map, at each distance; and the median footprint std in texels."""
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.setitem(grender.BAKE_SETTINGS, "intrinsic_roughness", sr)
    size = exemplar.shape[0]
    np.save(tmp_path / "exemplar.npy", encode_normals(exemplar))
    nm = _scene(tmp_path / "exemplar.npy", 1.0, size).objects[0].material.normal_map.load()
    wn = baked_tiles(nm, wang)
    idx = periodic_index_map(ny, ny, rng=3)
    big = assemble(wn.wang, idx)
    assert big.shape[0] == size  # the same texel scale for both methods
    np.save(tmp_path / "assembled.npy", encode_normals(big))
    rows = []
    for d in distances:
        sw = _scene(tmp_path / "exemplar.npy", d, size)
        sd = _scene(tmp_path / "assembled.npy", d, size)
        a = render_wang(sw, RenderSettings(), index=idx, wang=wang)
        b = render(sd, "glints-direct")
        from prefilter.render.camera import gbuffer_at

        xy = np.stack(np.meshgrid(np.arange(32) + 0.5, np.arange(24) + 0.5), -1)
        g = gbuffer_at(sd, xy).reshape(-1)
        sp = grender.footprints(g.select(g.hit), (size, size))[1]
        rows.append((float(flip(a, b).mean), float(a.mean() / b.mean()), float(np.median(sp))))
    # the same tiles in another arrangement (the hashing): another surface
    sw = _scene(tmp_path / "exemplar.npy", distances[0], size)
    other = float(flip(render_wang(sw, RenderSettings(), wang=wang), b).mean)
    return rows, wn, other


def test_index_map_equals_direct_on_assembled_map(tmp_path, monkeypatch):
    """Uncompressed per-tile pyramids, T = 8 on a 32^2 exemplar (a periodic 4 x 4 tiling), 32 x
    24 pixels: near / mid / far frames (median footprint std 0.58 / 2.3 / 9.3 texels: the
    direct, per-tile and tile-type-share regimes) against glints-direct on the assembled map.
    What differs: the bilinear NDF lookup (pixel pitch 0.78 intrinsic stds) and the shares
    regime's in-tile moments (quadratic in the texel's place in its tile). Measured FLIP
    0.0024 / 0.024 / 0.025, mean ratios 1.000 / 1.000 / 1.000; the hashed tiling instead of the
    index map: 0.66 at near."""
    exemplar = sinusoid(32, ax=0.3, ay=0.25, px=16, py=8)
    wang = dict(tile=8, band=2.0, ndf_res=32, support=1.0, intrinsic_roughness=0.08, rank=0,
                uniform_tiles=64.0)
    rows, wn, other = _assembled_vs_direct(tmp_path, monkeypatch, exemplar, wang, 0.08,
                                           (0.25, 1.0, 4.0), 4)
    print(rows, other)
    assert wn.block == 0 and wn.wang.size == 8
    assert rows[0][2] < wn.min_sigma <= rows[1][2] < wn.wide_sigma <= rows[2][2]  # 3 regimes
    for (f, ratio, _), bound in zip(rows, (0.01, 0.04, 0.04)):
        assert f < bound and abs(ratio - 1.0) < 0.01
    assert other > 0.3


def test_direct_mode_is_glints_direct_on_assembled_map(tmp_path, monkeypatch):
    """``direct=True`` (the direct P-NDF of the tiling at every footprint, no range queries)
    is ``glints-direct`` on the assembled map under point and environment lights: the same
    samples and NDF, pixel by pixel, at footprints of every regime (median 0.58 / 2.3 / 9.3
    texels, T = 8). Measured mean |difference| / mean <= 7.4e-7; ``ranges=False`` without
    ``direct`` (the per-tile pyramids and shares at the same samples) 0.002-0.0096. Quad lights:
    light samples where ``glints-direct`` uses MIS (frame means: ``test_quad_light_mean_...``),
    so ``direct`` against ``ranges=False`` at the same light samples: 0.0014-0.0050."""
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.setitem(grender.BAKE_SETTINGS, "intrinsic_roughness", 0.08)
    exemplar = sinusoid(32, ax=0.3, ay=0.25, px=16, py=8)
    wang = dict(tile=8, band=2.0, ndf_res=32, support=1.0, intrinsic_roughness=0.08, rank=0,
                uniform_tiles=64.0)
    np.save(tmp_path / "exemplar.npy", encode_normals(exemplar))
    nm = _scene(tmp_path / "exemplar.npy", 1.0, 32).objects[0].material.normal_map.load()
    wn = baked_tiles(nm, wang)
    idx = periodic_index_map(4, 4, rng=3)
    np.save(tmp_path / "assembled.npy", encode_normals(assemble(wn.wang, idx)))
    for lights in ("point", "environment", "quad"):
        for d in (0.25, 1.0, 4.0):
            specs = []
            for name in ("exemplar", "assembled"):
                sc = grender.measurement_scene(d, size=32, width=16, height=12, lights=lights)
                sc["objects"][0]["material"]["normal_map"] = str(tmp_path / f"{name}.npy")
                specs.append(load_scene(sc))
            a = render_wang(specs[0], RenderSettings(seed=2), index=idx, wang=wang, direct=True)
            c = render_wang(specs[0], RenderSettings(seed=2), index=idx, wang=wang,
                            ranges=False)
            if lights == "quad":
                approx = _rel_pixels(c, a)
                print(lights, d, approx)
                assert 1e-4 < approx < 0.03
                continue
            b = render(specs[1], "glints-direct", seed=2)
            same, approx = _rel_pixels(a, b), _rel_pixels(c, b)
            print(lights, d, same, approx)
            assert b.mean() > 0 and same < 1e-5
            assert 1e-4 < approx < 0.03
    # the registered method's variants: the same frames (the hashed tiling)
    monkeypatch.setenv("PREFILTER_GLINTS_WANG_SETTINGS", json.dumps(wang))
    for est, kw in (("prefiltered", {}), ("samples", dict(ranges=False)),
                    ("direct", dict(direct=True))):
        a = render(specs[0], "glints-wang", seed=1, params={"estimator": est})
        b = render_wang(specs[0], RenderSettings(seed=1), **kw)
        assert a.tobytes() == b.tobytes()
    with pytest.raises(PrefilterError, match="estimator"):
        render(specs[0], "glints-wang", params={"estimator": "exact"})


def _dependent_points(wn, idx, c, sp, s, sr):
    """Point densities ``(n_s,)`` at ``s (n_s, 2)`` of the dependent texels under one footprint
    over the assembled index map (numpy; pndf.elements' exact Jacobians; pndf's weights and
    normalisation and element cut)."""
    from prefilter.glints.pndf import SIGMA_H, TRUNCATION, elements

    big = assemble(wn.wang, idx)
    s_el, J = elements(big)
    T, H = wn.wang.size, big.shape[0]
    tot2 = sp * sp + SIGMA_H**2
    rad = TRUNCATION * np.sqrt(tot2)
    xs = np.arange(np.ceil(c[0] - rad - 0.5), np.floor(c[0] + rad - 0.5) + 1).astype(int)
    ys = np.arange(np.ceil(c[1] - rad - 0.5), np.floor(c[1] + rad - 0.5) + 1).astype(int)
    wx = np.exp(-(c[0] - xs - 0.5) ** 2 / (2 * tot2))
    wy = np.exp(-(c[1] - ys - 0.5) ** 2 / (2 * tot2))
    dep = np.zeros((T, T), bool)
    dep[wn.dependent[:, 0], wn.dependent[:, 1]] = True
    f, var = SIGMA_H**2 / tot2, sp * sp * SIGMA_H**2 / tot2
    out = np.zeros(len(s))
    for y, w_y in zip(ys, wy):
        for x, w_x in zip(xs, wx):
            if not dep[y % T, x % T]:
                continue
            jj = J[y % H, x % H]
            d = np.array([c[0] - x - 0.5, c[1] - y - 0.5])
            cov = sr * sr * np.eye(2) + var * jj @ jj.T
            e = s - (s_el[y % H, x % H] + f * jj @ d)
            quad = np.einsum("ni,ij,nj->n", e, np.linalg.inv(cov), e)
            g = np.exp(-0.5 * quad) / (2 * np.pi * np.sqrt(np.linalg.det(cov)))
            out += w_y * w_x * np.where(quad < 8 * TRUNCATION**2, g, 0.0)
    return out / (wx.sum() * wy.sum())


def test_bilinear_points(wn_pair):
    """ndf_points(bilinear=True): the tent-weighted sum of ndf at the 4 nearest pixel centres
    (outside the support: 0) for the pyramids, plus the dependent texels' point densities; the
    direct P-NDF's point value (pndf on the assembled tiles) below min_sigma; all with the
    given roughness where evaluated at the point."""
    from dataclasses import replace

    from prefilter.glints.wang import pndf_explicit

    wn, wc = wn_pair
    rng = np.random.default_rng(1)
    n_f, n_s = 40, 6
    c = rng.uniform(0, 96, (n_f, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(60.0), n_f))
    s = rng.uniform(-0.55, 0.55, (n_f, n_s, 2))
    h = 2 * wn.support / wn.resolution
    f = (s + wn.support) / h - 0.5
    p = np.floor(f)
    t = f - p
    idx = index_map(wn.wang, 12, 12)
    direct = sp < wn.min_sigma
    tiles = ~direct & (sp < wn.wide_sigma)
    assert direct.sum() > 2 and tiles.sum() > 2 and (~direct & ~tiles).sum() > 2
    dep = np.zeros((n_f, n_s))
    for k in np.flatnonzero(tiles):
        dep[k] = _dependent_points(wn, idx, c[k], sp[k], s[k], 0.03)
    assert dep.max() > 0  # the dependent texels are seen
    for w in (wn, wc):
        got = ndf_points(w, c[:, None], sp[:, None], s, index=idx, bilinear=True,
                         point_roughness=0.03)
        pyr = replace(w, dependent=np.zeros((0, 2), np.int64))  # the pyramids alone
        want = np.zeros_like(got)
        for a in (0, 1):
            for b in (0, 1):
                wt = (t[..., 1] if a else 1 - t[..., 1]) * (t[..., 0] if b else 1 - t[..., 0])
                cen = np.stack([p[..., 0] + b, p[..., 1] + a], -1)
                inside = np.all((cen >= 0) & (cen < wn.resolution), -1)
                cen = (cen + 0.5) * h - wn.support
                want += wt * inside * np.stack([ndf(pyr, c[k], sp[k], cen[k], index=idx)
                                                for k in range(n_f)])
        want += dep
        for k in np.flatnonzero(direct):
            want[k] = pndf_explicit(wn.wang, idx, c[k], sp[k], s[k], 0.03)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
        assert not np.allclose(got, ndf_points(w, c[:, None], sp[:, None], s, index=idx),
                               rtol=1e-2)


def test_dependent_texels_by_vertex_equal_neighbour_lookups(wn_pair):
    """On the implicit tiling the bilinear point queries read the dependent texels' elements
    from the vertex-configuration table (``vertex_elements``); given the same tiles as an
    explicit index map they look each neighbour up: the same values (the implicit path cuts the
    elements it evaluates at 6 stds like ``glints-direct``, the explicit one at ``2 TRUNCATION``
    stds), and the dependent texels count."""
    from dataclasses import replace

    wn, wc = wn_pair
    T = wn.wang.size
    idx = index_map(wn.wang, 40, 40)  # tiles (0..39, 0..39) of the implicit tiling
    rng = np.random.default_rng(3)
    n_f = 40
    s = rng.uniform(-0.45, 0.45, (n_f, 6, 2))
    c = rng.uniform(8 * T, 32 * T, (n_f, 2))  # the windows stay inside the map
    # an element dropped by the 6-std cut has a density below exp(-18) of the sharpest element's
    # peak (weights normalised to 1)
    atol = np.exp(-18.0) / (2 * np.pi * 0.03**2)
    for sp in (rng.uniform(0.3, wn.min_sigma, n_f), rng.uniform(wn.min_sigma, wn.wide_sigma, n_f)):
        for w in (wn, wc):
            got = ndf_points(w, c[:, None], sp[:, None], s, bilinear=True, point_roughness=0.03)
            want = ndf_points(w, c[:, None], sp[:, None], s, index=idx, bilinear=True,
                              point_roughness=0.03)
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=atol)
        pyr = replace(w, dependent=np.zeros((0, 2), np.int64))
        alone = ndf_points(pyr, c[:, None], sp[:, None], s, bilinear=True,
                           point_roughness=0.03)
        assert np.abs(got - alone).max() > 1e-3 * got.max()


def test_errors(tmp_path, monkeypatch):
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    assert "glints-wang" in available() and "Wang" in describe("glints-wang")
    with pytest.raises(PrefilterError, match="settings: expected keys among"):
        wang_settings({"tiles": 8})
    monkeypatch.setenv("PREFILTER_GLINTS_WANG_SETTINGS", '{"ndf_res": 16, "rank": 0}')
    assert wang_settings({"rank": 2})["ndf_res"] == 16 and wang_settings()["rank"] == 0
    assert wang_settings({"rank": 2})["rank"] == 2
    for bad in ("[1]", "{nope", '{"res": 1}'):
        monkeypatch.setenv("PREFILTER_GLINTS_WANG_SETTINGS", bad)
        with pytest.raises(PrefilterError, match="PREFILTER_GLINTS_WANG_SETTINGS: expected"):
            wang_settings()
    monkeypatch.delenv("PREFILTER_GLINTS_WANG_SETTINGS")
    with pytest.raises(PrefilterError, match="settings.tile: expected a value of type int"):
        wang_settings({"tile": 8.5})
    with pytest.raises(PrefilterError, match="settings.bilinear: expected a value of type bool"):
        wang_settings({"bilinear": 1})
    one = wang_settings({"wide_tiles": 1})
    assert type(one["wide_tiles"]) is float and one == wang_settings({"wide_tiles": 1.0})
    nm = sinusoid(8, 0.2, 0.2, 8, 8)
    assert cache_path(nm, {"wide_tiles": 1}) == cache_path(nm, {"wide_tiles": 1.0})
    assert cache_path(nm, {"seed": 1}) != cache_path(nm)
    assert len({cache_path(nm, {"code_bits": b}) for b in (0, 8, 16)}) == 3
    with pytest.raises(PrefilterError, match=r"settings.code_bits: expected one of \(0, 8, 16\), "
                                             "got 12"):
        wang_settings({"code_bits": 12})
    sc = grender.measurement_scene(1.0, size=8, width=4, height=3, lights="quad")
    sc["lights"][0]["texture"] = {"procedural": "noise", "size": 4}
    with pytest.raises(PrefilterError, match=r"lights\[0\]: method 'glints-wang' expected "
                                             "untextured quad, point, directional or environment "
                                             "lights, got a textured quad"):
        render(load_scene(sc), "glints-wang")
    sc = grender.measurement_scene(1.0, size=8, width=4, height=3)
    del sc["objects"][0]["material"]["normal_map"]
    with pytest.raises(PrefilterError, match="normal_map: method 'glints-wang' expected a normal"):
        render(load_scene(sc), "glints-wang")
    wn = bake_tiles(synthesize(sinusoid(8, 0.2, 0.2, 8, 8), tile=4, band=1.0), ndf_res=4)
    with pytest.raises(PrefilterError, match="index: expected a 2D integer tile index map"):
        ndf_points(wn, (1.0, 1.0), 2.0, (0.0, 0.0), index=np.full((2, 2), 16))
    with pytest.raises(PrefilterError, match="wn: expected a TiledNDF"):
        ndf_points(object(), (1.0, 1.0), 2.0, (0.0, 0.0))
    with pytest.raises(PrefilterError, match="tile: expected an even tile size"):
        baked_tiles(sinusoid(8, 0.2, 0.2, 8, 8), {"tile": 5})
    assert tile_size(32, (8, 12)) == 8 and tile_size(32, (3, 3)) == 4
    assert tile_size(32, (128, 128)) == 32


def test_cache_path_is_the_baked_file(tmp_path, monkeypatch):
    """cache_path names the file baked_tiles writes (the exemplar validated once, the tile size
    capped), an 8-bit version-2 file by default, decoded at load."""
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.delenv("PREFILTER_GLINTS_WANG_SETTINGS", raising=False)
    nm = sinusoid(8, 0.2, 0.2, 8, 8).astype(np.float32)
    over = {"ndf_res": 8, "rank": 2, "block": 4, "n_iter_max": 3, "tile": 32}
    wn = baked_tiles(nm, over)
    assert [p.name for p in tmp_path.glob("wang-*.npz")] == [cache_path(nm, over).name]
    with np.load(cache_path(nm, over)) as z:
        header = json.loads(str(z["header"]))
    assert header["version"] == 4 and header["settings"]["code_bits"] == 8
    assert wn.wang.size == 8 and wn.block == 4 and wn.images[0][2].dtype == np.float32


def test_cache_keys_record_the_fit_version(tmp_path, monkeypatch):
    """The render and Wang-tile cache keys change with the CP fit's version (files fitted by an
    older fit are not reused)."""
    from prefilter.glints import cp as cpmod

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    nm = sinusoid(8, 0.2, 0.2, 8, 8)
    st = dict(grender.BAKE_SETTINGS)
    before = settings_key(st), cache_path(nm)
    monkeypatch.setattr(cpmod, "FIT_VERSION", cpmod.FIT_VERSION + 1)
    after = settings_key(st), cache_path(nm)
    assert before[0] != after[0] and before[1] != after[1]


def test_render_key_records_the_exact_budget_rule(tmp_path, monkeypatch):
    """Bake settings with exact levels key on the budget rule; the
    Wang-tile key (no exact levels) does not."""
    from prefilter.glints import bake as gbake

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    nm = sinusoid(8, 0.2, 0.2, 8, 8)
    st = dict(grender.BAKE_SETTINGS)
    assert st.get("exact_from_level") is not None
    no_exact = {k: v for k, v in st.items() if k not in ("exact_from_level", "exact_cell")}
    before = settings_key(st), settings_key(no_exact), cache_path(nm)
    monkeypatch.setattr(gbake, "EXACT_BUDGET_RULE", gbake.EXACT_BUDGET_RULE - 1)
    after = settings_key(st), settings_key(no_exact), cache_path(nm)
    assert before[0] != after[0] and before[1:] == after[1:]


@pytest.mark.slow
def test_compressed_index_map_against_direct(tmp_path, monkeypatch):
    """CP-compressed per-tile pyramids (rank 16, blocks 16), T = 16 on a 64^2 Gaussian
    heightfield exemplar, R = 64 over the whole disk, intrinsic roughness 0.04 (pixel 0.78
    stds, as the render default): frames with median footprints 2.3 / 4.6 / 18.6 texels (per-tile
    regime from 2.5, shares from 8) against glints-direct on the assembled map. Measured FLIP
    0.049 / 0.046 / 0.018 (the default 8-bit file), mean ratios within 0.14 %; the hashed
    tiling: 0.41; 4.1 MB held. ~15-60 s."""
    from maps import gaussian_heightfield

    exemplar = gaussian_heightfield(64, corr=3, slope_std=0.15, seed=2)[0]
    wang = dict(tile=16, band=2.0, ndf_res=64, support=1.0, intrinsic_roughness=0.04, rank=16,
                block=16)
    rows, wn, other = _assembled_vs_direct(tmp_path, monkeypatch, exemplar, wang, 0.04,
                                           (0.5, 1.0, 4.0), 4)
    print(rows, other, wn.cp_error, wn.nbytes)
    assert wn.block == 16
    assert rows[0][2] < wn.wide_sigma <= rows[2][2]
    for f, ratio, _ in rows:
        assert f < 0.09 and abs(ratio - 1.0) < 0.015
    assert other > 4 * max(r[0] for r in rows)


def test_directional_and_point_lights_add_up(tmp_path, monkeypatch):
    """A directional light shades like a point light of the same irradiance at every point
    (the same direction: a point light far away), and two lights add (one batched query)."""
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path))
    monkeypatch.setenv("PREFILTER_GLINTS_WANG_SETTINGS",
                       '{"ndf_res": 16, "rank": 0, "intrinsic_roughness": 0.1}')
    sc = grender.measurement_scene(1.0, size=8, width=8, height=6)
    sc["objects"][0]["material"]["base_color"] = [0.1, 0.2, 0.3]
    d = np.array([0.0, 0.6, -1.0]) / np.linalg.norm([0.0, 0.6, -1.0])
    far = 1e5  # far enough to be directional at rtol 1e-4, inside the scene domain (1e6)
    point = {"type": "point", "position": list(d * far), "intensity": [far * far * 2.0] * 3}
    sun = {"type": "directional", "direction": list(-d), "irradiance": [2.0] * 3}
    imgs = {}
    for name, lights in (("point", [point]), ("sun", [sun]), ("both", [point, sun])):
        sc["lights"] = lights
        imgs[name] = render(load_scene(sc), "glints-wang")
    assert imgs["sun"].max() > 0 and np.all(np.isfinite(imgs["both"]))
    np.testing.assert_allclose(imgs["point"], imgs["sun"], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(imgs["both"], imgs["point"] + imgs["sun"], rtol=1e-5, atol=1e-6)


# -- quad and environment lights --------------------------------------------------------------

#: Flat exemplar (every normal (0, 0, 1)): the footprint NDF is the intrinsic Gaussian lobe
#: whatever the footprint, so glints-wang and glints-direct integrate the same smooth lobe.
FLAT_SR = 0.1
FLAT_WANG = dict(tile=8, band=2.0, ndf_res=32, support=1.0, intrinsic_roughness=FLAT_SR, rank=0)


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    """``scene(d, lights, width, height)`` on a 16^2 flat exemplar (Wang tiles of 8, R = 32
    uncompressed; glints-direct at the same intrinsic roughness), private glints cache."""
    d = tmp_path_factory.mktemp("flat")
    np.save(d / "flat.npy", encode_normals(np.broadcast_to([0.0, 0.0, 1.0], (16, 16, 3)).copy()))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PREFILTER_GLINTS_CACHE", str(d))
        mp.delenv("PREFILTER_GLINTS_WANG_SETTINGS", raising=False)
        mp.setitem(grender.BAKE_SETTINGS, "intrinsic_roughness", FLAT_SR)

        def scene(dist, lights, width=16, height=12):
            sc = grender.measurement_scene(dist, size=16, width=width, height=height,
                                           lights=lights)
            sc["objects"][0]["material"]["normal_map"] = str(d / "flat.npy")
            sc["objects"][0]["material"]["base_color"] = [0.05, 0.1, 0.0]
            return load_scene(sc)

        yield scene


def _rel_pixels(a, b):
    return float(np.abs(a - b).mean() / b.mean())


def test_environment_same_draws_as_direct(flat):
    """Environment light, flat exemplar: for the same seed glints-wang draws glints-direct's SG
    light samples (the glints uniforms layout), so the frames agree pixel by pixel up to the NDF
    lookup (measured mean |diff| / mean 0.0027 / 0.0091 near / far at spp 2: the direct regime
    is exact, the pyramids bilinear), while another seed differs by the Monte Carlo noise
    (0.68)."""
    for dist in (0.5, 2.0):
        sc = flat(dist, "environment")
        a = render_wang(sc, RenderSettings(seed=3), wang=FLAT_WANG)
        b = render(sc, "glints-direct", seed=3)
        other = render(sc, "glints-direct", seed=4)
        same, diff = _rel_pixels(a, b), _rel_pixels(a, other)
        print(dist, same, diff, a.mean() / b.mean())
        assert a.max() > 0 and np.all(np.isfinite(a))
        assert same < 0.03 and diff > 0.3
        assert abs(a.mean() / b.mean() - 1.0) < 0.01


def test_quad_light_mean_matches_direct(flat):
    """Quad light, flat exemplar: glints-wang's light sampling and glints-direct's MIS estimate
    the same integral. Frame means over independent seeds (wang 0-7, direct 100-107) agree
    within 4 standard errors measured here, near (direct regime) and far (pyramids). Measured
    (spp 1): z = -1.45 / -1.59, standard error 1.1 % of the mean (direct's seeds 100-107 are
    high: near with 48 seeds each, wang 0-47 against direct 1000-1047 z = -0.88, against direct
    0-47 z = +1.08; frame-mean std 1.9 % (wang) and 4.0 % (direct) of the mean)."""
    for dist in (0.5, 2.0):
        sc = flat(dist, "quad")
        a = np.array([render_wang(sc, RenderSettings(seed=s), wang=FLAT_WANG).mean()
                      for s in range(8)])
        b = np.array([render(sc, "glints-direct", seed=100 + s).mean() for s in range(8)])
        se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
        print(dist, a.mean(), b.mean(), se)
        assert 0 < se < 0.03 * b.mean()
        assert abs(a.mean() - b.mean()) < 4 * se


def test_lights_deterministic(flat):
    """Point, quad and environment lights together: the same seed gives the same bytes, another
    seed another frame; a bare shade_wang call without the uniforms is an error."""
    from prefilter.glints.wang_render import QUAD_SAMPLES, quad_uniforms, shade_wang
    from prefilter.render.camera import gbuffer_at

    spec = flat(1.0, "quad", 8, 6).to_dict()
    spec["lights"] += (grender.measurement_scene(1.0, lights="environment")["lights"]
                       + grender.measurement_scene(1.0)["lights"])
    sc = load_scene(spec)
    a, b, c = (render_wang(sc, RenderSettings(seed=s, spp=2), wang=FLAT_WANG) for s in (5, 5, 6))
    assert a.tobytes() == b.tobytes() and a.tobytes() != c.tobytes()
    assert a.dtype == np.float32 and np.all(np.isfinite(a)) and a.min() >= 0
    xy = np.stack(np.meshgrid(np.arange(8) + 0.5, np.arange(6) + 0.5), -1)
    g = gbuffer_at(sc, xy).reshape(-1)
    g = g.select(g.hit)
    with pytest.raises(PrefilterError, match="u: expected uniforms for the quad"):
        shade_wang(sc, g, settings=FLAT_WANG)
    with pytest.raises(PrefilterError, match=r"u: expected uniforms of shape \(48, >= 68\)"):
        shade_wang(sc, g, settings=FLAT_WANG, u=np.zeros((len(g.uv), 3)))
    # the first QUAD_MIS light samples are glints-direct's (uniforms 0-1 of each pair)
    u = np.random.default_rng(0).random((5, 44))
    q = quad_uniforms(u, 0)
    assert q.shape == (5, QUAD_SAMPLES, 2)
    np.testing.assert_array_equal(q[:, :4], u.reshape(5, 4, 11)[:, :, :2])
    np.testing.assert_array_equal(q[:, 4:8], u.reshape(5, 4, 11)[:, :, 2:4])
    with pytest.raises(PrefilterError, match="n: expected 1 to 20 light samples, got 21"):
        quad_uniforms(u, 0, 21)
    with pytest.raises(PrefilterError, match=r"u: expected uniforms of shape \(N, >= 88\)"):
        quad_uniforms(u, 1)
