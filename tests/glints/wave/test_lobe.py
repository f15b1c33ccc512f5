"""RGB queries, BRDF and luminance sampling of a baked wave-optics map, against the direct model
(uncompressed coherence-area images) and the sampler's own density (chi-square)."""

import numpy as np
import pytest
from scipy import stats

from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.brdf import half, vcavity_g2
from prefilter.glints.wave import bake as wb
from prefilter.glints.wave import heightfield as hfm
from prefilter.glints.wave import lobe
from prefilter.glints.wave.direct import DirectWave

R, S = 64, 0.25
H = 2 * S / R


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    hf = hfm.isotropic_noise(32, seed=3)
    out = tmp_path_factory.mktemp("wave") / "w.npz"
    summary = wb.bake_wave(hf, out, rank=16, progress=False)
    return hf, out, wb.load_wave(out), summary


def grid():
    x = -S + (np.arange(R) + 0.5) * H
    X, Y = np.meshgrid(x, x)
    return np.stack([X, Y], -1).reshape(-1, 2)


def test_bake_summary_and_files(baked):
    hf, out, wm, summary = baked
    assert [p.exists() for p in wb.channel_paths(out)] == [True] * 3
    assert summary["ratio"] < 0.2 and max(summary["rel_l2_error_per_channel"]) < 0.1
    assert wm.level0_key.startswith("{") and hf.digest in wm.level0_key


def test_channels_share_one_pyramid(tmp_path, monkeypatch):
    """Each channel stops adding levels where its own images converge; a channel that stopped
    below another is baked again up to the tallest, so the three load together."""
    hf = hfm.isotropic_noise(32, seed=3)
    real, calls = wb.bake, []

    def green_stops_early(nm, path, **kw):
        first_green = str(path).endswith(".G.npz") and not any(".G." in c for c, _ in calls)
        calls.append((str(path), kw.get("max_levels")))
        return real(nm, path, **(dict(kw, max_levels=2) if first_green else kw))

    monkeypatch.setattr(wb, "bake", green_stops_early)
    out = tmp_path / "w.npz"
    wb.bake_wave(hf, out, rank=4, progress=False)
    wm = wb.load_wave(out)
    n = {gm.pyramid.n_levels for gm in wm.channels}
    assert len(n) == 1 and n.pop() > 2
    assert [c.rsplit(".", 2)[1] for c, _ in calls] == ["R", "G", "B", "G"]
    assert calls[-1][1] == wm.pyramid.n_levels


@pytest.mark.slow
def test_bake_resumes_from_its_parts(baked, tmp_path, monkeypatch):
    """A bake whose outputs are gone resumes from its checkpoints (no NDF image recomputed) and
    writes the same bytes."""
    hf, out, _, _ = baked
    again = tmp_path / "w.npz"
    wb.bake_wave(hf, again, rank=16, progress=False, keep_parts=True)
    for p in wb.channel_paths(again):
        p.unlink()

    def fail(*args, **kwargs):
        raise AssertionError("level-0 images recomputed")

    monkeypatch.setattr(wb, "rgb_images", fail)
    wb.bake_wave(hf, again, rank=16, progress=False)
    for a, b in zip(wb.channel_paths(out), wb.channel_paths(again)):
        assert a.read_bytes() == b.read_bytes()


def test_load_rejects_a_missing_or_foreign_channel(baked, tmp_path):
    _, out, _, _ = baked
    with pytest.raises(TableFileError, match="missing channel"):
        wb.load_wave(tmp_path / "none.npz")
    paths = wb.channel_paths(tmp_path / "mixed.npz")
    for p, q in zip(wb.channel_paths(out), paths):
        q.write_bytes(p.read_bytes())
    paths[1].write_bytes(wb.channel_paths(out)[0].read_bytes())  # R stored as G
    with pytest.raises(TableFileError, match="channel G"):
        wb.load_wave(tmp_path / "mixed.npz")


@pytest.mark.parametrize("c, sp", [((12.5, 8.5), 4.0), ((20.3, 3.1), 6.0), ((7.0, 25.0), 11.0),
                                   ((1.0, 1.0), 30.0)])
def test_compressed_point_queries_match_the_direct_model(baked, c, sp):
    hf, _, wm, _ = baked
    dw = DirectWave(hf)
    s = grid()
    a = lobe.point_rgb(wm, np.broadcast_to(c, s.shape), np.full(len(s), sp), s)
    b = dw.point(np.broadcast_to(c, s.shape), np.full(len(s), sp), s)
    assert np.linalg.norm(a - b) / np.linalg.norm(b) < 0.12
    # energy of each channel within 1 % of the direct model's
    assert np.allclose(a.sum(0), b.sum(0), rtol=0.01)


def test_range_rgb_is_the_mean_of_pixel_values(baked):
    _, _, wm, _ = baked
    c, sp = (10.5, 14.5), 5.0
    s = grid().reshape(R, R, 2)
    pix = lobe.point_rgb(wm, c, sp, s, interp="trilinear", bilinear=False)
    i0, i1, j0, j1 = 20, 36, 24, 40
    rng = lobe.range_rgb(wm, c, sp, [-S + j0 * H, -S + i0 * H], [-S + j1 * H, -S + i1 * H])
    np.testing.assert_allclose(rng, pix[i0:i1, j0:j1].mean(axis=(0, 1)), rtol=1e-4)


def test_sampling_pdf_and_chi_square(baked):
    _, _, wm, _ = baked
    c, sp, n = (17.3, 9.8), 5.0, 30_000
    cc = np.broadcast_to(c, (n, 2))
    s, pdf = lobe.sample_s(wm, cc, np.full(n, sp), 1)
    np.testing.assert_allclose(pdf, lobe.pdf_s(wm, cc[:n], np.full(n, sp), s), rtol=1e-6)
    assert np.all(pdf > 0)
    # chi-square against the luminance image, pixel bins pooled to >= 5 expected samples
    v = lobe.pdf_s(wm, np.broadcast_to(c, (R * R, 2)), np.full(R * R, sp), grid())
    exp = n * v / v.sum()
    ij = np.floor((s + S) / (2 * S) * R).astype(int)
    obs = np.zeros((R, R))
    np.add.at(obs, (ij[:, 1], ij[:, 0]), 1.0)
    obs = obs.ravel()
    assert obs[exp == 0].sum() == 0
    order = np.argsort(exp)
    e, o = exp[order], obs[order]
    keep = e >= 5
    groups = np.floor(np.cumsum(e[~keep]) / 5.0).astype(int)
    pe, po = np.bincount(groups, e[~keep]), np.bincount(groups, o[~keep])
    E = np.concatenate([e[keep], pe[pe > 0]])
    O = np.concatenate([o[keep], po[pe > 0]])
    assert stats.chi2.sf(np.sum((O - E) ** 2 / E), len(E) - 1) > 1e-3


def test_sample_wi_weights_are_the_brdf_over_the_pdf(baked):
    _, _, wm, _ = baked
    n = 4000
    wo = np.tile([0.2, -0.1, np.sqrt(1 - 0.05)], (n, 1))
    c, sp = np.broadcast_to((5.5, 21.5), (n, 2)), np.full(n, 6.0)
    wi, pdf = lobe.sample_wi(wm, c, sp, wo, 2)
    ok = pdf > 0
    f = lobe.brdf_cos_rgb(wm, c[ok], sp[ok], wo[ok], wi[ok], interp="trilinear",
                          bilinear=False)
    # the luminance of f / pdf is F G wi_z... bounded: G <= 1, F <= 1, and the density ratio is the
    # luminance ratio of D_c at the drawn s (no infinite weights)
    w = f / pdf[ok, None]
    # luminance of the weight: F G (wo.m) / (wo_z m_z) M_Y (f0 = 1: F = 1), i.e. the per-channel
    # weights are D_c / D_Y times a bounded factor
    m = half(wo[ok], wi[ok])
    G = vcavity_g2(wo[ok], wi[ok], m)
    M_Y = lobe.masses(wm, c[:1], sp[:1]) @ lobe.LUMINANCE
    expect = G * np.sum(wo[ok] * m, -1) / (wo[ok, 2] * m[:, 2]) * M_Y
    np.testing.assert_allclose(w @ lobe.LUMINANCE, expect, rtol=1e-6)


def test_wrong_map_type():
    with pytest.raises(PrefilterError, match="wm: expected a WaveMap"):
        lobe.point_rgb("x.npz", (0, 0), 4.0, (0, 0))


def test_direct_lookup_fades_over_the_outer_half_pixel_as_the_compressed_one(baked):
    """The direct model's bilinear lookup uses the compressed lookup's taps: zero padding around
    the image, so a value fades to 0 from the outer pixel centres to half a pixel beyond the
    support, and both methods are 0 further out."""
    hf, _, wm, _ = baked
    dw = DirectWave(hf)
    c = (8.5, 12.5)  # a lattice centre: footprints at sigma0 see its image alone
    img = np.pad(dw.images[3, 2], ((0, 0), (1, 1), (1, 1)))  # (3, R + 2, R + 2)
    x = np.array([-S - 0.7 * H, -S - 0.3 * H, -S + 0.2 * H, -S + 0.7 * H, 0.01, S - 0.2 * H,
                  S - 0.6 * H, S + 0.1 * H, S + 0.6 * H])
    X, Y = np.meshgrid(x, x)
    s = np.stack([X, Y], -1).reshape(-1, 2)
    got = dw.point(np.broadcast_to(c, s.shape), np.full(len(s), 4.0), s)
    # reference: bilinear on the zero-padded image, whose pixel k is centred at s(k) with
    # (s(k) + S) / H = k - 0.5
    g = (s + S) / H + 0.5
    i0 = np.floor(g).astype(int)
    t = g - i0
    want = np.zeros((len(s), 3))
    for dy in (0, 1):
        for dx in (0, 1):
            iy, ix = i0[:, 1] + dy, i0[:, 0] + dx
            ok = (iy >= 0) & (iy <= R + 1) & (ix >= 0) & (ix <= R + 1)
            w = (t[:, 1] if dy else 1 - t[:, 1]) * (t[:, 0] if dx else 1 - t[:, 0]) * ok
            want += w[:, None] * img[:, np.clip(iy, 0, R + 1), np.clip(ix, 0, R + 1)].T
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9)
    outside = (np.abs(s) > S + 0.5 * H).any(1)
    assert np.all(got[outside] == 0) and np.all(got[~outside].sum(1) > 0)
    comp = lobe.point_rgb(wm, np.broadcast_to(c, s.shape), np.full(len(s), 4.0), s)
    assert np.all(comp[outside] == 0)


@pytest.mark.parametrize("c, sp", [((12.5, 8.5), 5.0), ((20.3, 3.1), 8.0), ((7.0, 25.0), 15.0),
                                   ((1.0, 1.0), 30.0)])
def test_the_uncompressed_pyramid_is_the_direct_model(baked, c, sp):
    """The pyramid's filtering and Gaussian resampling reproduce the direct model's weights: the
    uncompressed pyramid's point values match it (the compressed map differs by the CP alone)."""
    from prefilter.glints.wave.direct import PyramidWave

    hf, _, wm, _ = baked
    dw = DirectWave(hf)
    s = grid()
    cc, spp = np.broadcast_to(c, s.shape), np.full(len(s), sp)
    a = PyramidWave(dw, wm.pyramid).point(cc, spp, s)
    b = dw.point(cc, spp, s)
    assert np.linalg.norm(a - b) / np.linalg.norm(b) < 0.005  # measured <= 9e-4
