"""Hierarchical NDF sampling (glints paper sec. 5.2) against the evaluated compressed NDF: pdf ==
normalised eval, chi-square in s (pixels and sub-pixels: block choice, quadtree and jitter), the
NDF-image histogram (relative L2), and the reflected-direction pdf by a chi-square on the sphere."""

import numpy as np
import pytest
from maps import sinusoid
from scipy import stats

from prefilter.errors import PrefilterError
from prefilter.glints import load, point
from prefilter.glints.bake import bake
from prefilter.glints.sample import mass, n_uniforms, ndf_pdf, sample_s, sample_wi
from prefilter.sphere import chi2_sphere

R, S = 64, 0.5
H = 2 * S / R


@pytest.fixture(scope="module", params=[16, 32], ids=["B16", "B32"])
def gm(request, tmp_path_factory):
    """Blocks of 16 pixels, and of 32 (the render bake's: a 5-level quadtree
    descent per block)."""
    out = tmp_path_factory.mktemp("gs") / "map.npz"
    bake(sinusoid(64, ax=0.25, ay=0.2, px=16, py=8), out, rank=16, ndf_res=R,
         block=request.param, support=S, cell=32, converge=0.0, progress=False)
    return load(out)


def pixel_values(gm, c, sp, sub=1):
    """Point-query values at the centres of an ``(R sub)^2`` grid of (sub-)pixels."""
    n = R * sub
    x = (np.arange(n) + 0.5) * (2 * S / n) - S
    X, Y = np.meshgrid(x, x)
    return point(gm, c, sp, np.stack([X, Y], -1))


def histogram(s, sub=1):
    n = R * sub
    ij = np.floor((s + S) / (2 * S) * n).astype(int)
    hist = np.zeros((n, n))
    np.add.at(hist, (ij[:, 1], ij[:, 0]), 1.0)
    return hist


FOOTPRINTS = [((10.3, 20.7), 2.5), ((33.0, 5.2), 6.0), ((50.1, 47.9), 13.0), ((3.0, 60.0), 90.0)]


def test_pdf_equals_normalised_eval(gm):
    rng = np.random.default_rng(7)
    c = rng.uniform(-10, 80, (200, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(200), 200))
    s, pdf = sample_s(gm, np.repeat(c, 50, 0), np.repeat(sp, 50), rng)
    ev = ndf_pdf(gm, np.repeat(c, 50, 0), np.repeat(sp, 50), s)
    assert np.all(pdf > 0)
    np.testing.assert_allclose(pdf, ev, rtol=2e-6)
    # the normalisation is the integral of the image: midpoint sum of point queries
    for (cc, spp) in FOOTPRINTS:
        assert mass(gm, cc, spp) == pytest.approx(pixel_values(gm, cc, spp).sum() * H * H,
                                                  rel=1e-5)


@pytest.mark.parametrize("c, sp", FOOTPRINTS)
def test_chi2_in_s(gm, c, sp):
    """Chi-square of 2x2 sub-pixel bins (tests the jitter too) against the eval image."""
    n = 100_000
    s, _ = sample_s(gm, np.broadcast_to(c, (n, 2)), np.full(n, sp), np.random.default_rng(1))
    obs = histogram(s, sub=2).ravel()
    v = pixel_values(gm, c, sp, sub=2).ravel()
    exp = n * v / v.sum()
    assert obs[exp == 0].sum() == 0
    order = np.argsort(exp)
    # pool the smallest bins into groups expecting >= 5 samples
    e, o = exp[order], obs[order]
    keep = e >= 5
    small_e, small_o = e[~keep], o[~keep]
    groups = np.floor(np.cumsum(small_e) / 5.0).astype(int)
    pe = np.bincount(groups, small_e)
    po = np.bincount(groups, small_o)
    E = np.concatenate([e[keep], pe[pe > 0]])
    O = np.concatenate([o[keep], po[pe > 0]])
    chi2 = np.sum((O - E) ** 2 / E)
    p = stats.chi2.sf(chi2, len(E) - 1)
    assert p > 1e-3, (chi2, len(E), p)


def _rel_l2(gm, c, sp, n, seed):
    s, _ = sample_s(gm, np.broadcast_to(c, (n, 2)), np.full(n, sp), np.random.default_rng(seed))
    hist = histogram(s) / (n * H * H)
    img = pixel_values(gm, c, sp) / mass(gm, c, sp)
    return np.linalg.norm(hist - img) / np.linalg.norm(img), img


def test_histogram_matches_ndf_image_fast(gm):
    """300k samples: relative L2 within 1.3x the multinomial noise expected at this count
    (~4.8 %: sqrt(sum p (1 - p) / n) / |p|); the 10M version (slow) checks the 2 % bound."""
    c, sp = (33.0, 5.2), 6.0
    n = 300_000
    err, img = _rel_l2(gm, c, sp, n, 3)
    p = img.ravel() * H * H
    noise = np.sqrt(np.sum(p * (1 - p)) / n) / np.linalg.norm(p)
    assert err < 1.3 * noise, (err, noise)


@pytest.mark.slow
@pytest.mark.parametrize("c, sp", FOOTPRINTS)
def test_histogram_matches_ndf_image_10M(gm, c, sp):
    if gm.block == 32:  # ~13 min per map; the fast histogram and chi-square tests cover B = 32
        pytest.skip("10M-sample histogram on the 16-pixel-block map only")
    err, _ = _rel_l2(gm, c, sp, 10_000_000, 4)
    assert err <= 0.02, err


def test_sample_wi_chi2_sphere(gm):
    """Reflected directions against pdf_s(h) h_z / (4 wo.h) on the sphere (a wide footprint)."""
    c, sp = (20.0, 40.0), 40.0
    wo = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    n = 200_000
    wi, pdf = sample_wi(gm, np.broadcast_to(c, (n, 2)), sp, wo, np.random.default_rng(5))
    assert np.all(pdf > 0)

    def density(w):
        h = w + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        p = ndf_pdf(gm, c, sp, h[..., :2]) * h[..., 2] / (4 * np.abs(np.sum(wo * h, -1)))
        return np.where(h[..., 2] > 0, p, 0.0)

    axis = -wo * np.array([1, 1, -1.0])
    res = chi2_sphere(wi, density, axis=axis, theta_max=1.2, res=(12, 24))
    assert res.passed(1e-3), res


def test_deterministic_and_validated(gm):
    c = np.broadcast_to((5.0, 6.0), (100, 2))
    a = sample_s(gm, c, 4.0, 11)
    b = sample_s(gm, c, 4.0, np.random.default_rng(11))
    assert a[0].tobytes() == b[0].tobytes()
    with pytest.raises(PrefilterError, match="u:"):
        sample_s(gm, c, 4.0, u=np.zeros((100, n_uniforms(gm) + 1)))
    with pytest.raises(PrefilterError, match="sigma_p"):
        sample_s(gm, c, -1.0)
    with pytest.raises(PrefilterError, match="gm"):
        sample_s("map.npz", c, 1.0)


def test_direct_sampling_chi2(gm):
    """Direct P-NDF sampling (footprints below level 0) against the exact pixel masses of
    ``pndf_image`` (independent integration), chi-square; pdf == pndf at the samples."""
    from prefilter.glints import pndf_image
    from prefilter.glints.pndf import pndf
    from prefilter.glints.surface import surface
    from prefilter.glints.sample import sample_s_direct

    nm = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)
    surf = surface(gm, nm)
    n = 100_000
    for c, sp in (((10.3, 20.7), 1.5), ((40.0, 33.3), 3.0)):
        s, pdf = sample_s_direct(surf, np.broadcast_to(c, (n, 2)), np.full(n, sp), 3)
        np.testing.assert_allclose(pdf, pndf(nm, c, sp, s), rtol=1e-12)
        inside = np.all(np.abs(s) < S, axis=-1)
        obs = histogram(s[inside]).ravel()
        exp = n * pndf_image(nm, c, sp, R, S).ravel() * H * H
        keep = exp >= 5
        O = np.append(obs[keep], obs[~keep].sum() + (n - inside.sum()))
        E = np.append(exp[keep], n - exp[keep].sum())
        chi2 = np.sum((O - E) ** 2 / E)
        assert stats.chi2.sf(chi2, len(E) - 1) > 1e-3, (chi2, len(E))


def test_sample_wi_surface_routes_small_footprints(gm):
    """With the normal map, footprints below sigma0 are sampled from the direct P-NDF: the
    returned pdf is pndf(h_xy) h_z / (4 wo.h), and the compressed one elsewhere."""
    from prefilter.glints.pndf import pndf
    from prefilter.glints.surface import surface

    nm = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)
    surf = surface(gm, nm)
    wo = np.array([0.3, 0.1, 0.0])
    wo[2] = np.sqrt(1 - 0.1)
    c = np.random.default_rng(2).uniform(0, 64, (400, 2))
    sp = np.where(np.arange(400) % 2 == 0, 1.0, 9.0)
    wi, pdf = sample_wi(surf, c, sp, wo, 5)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    ok = pdf > 0
    small = sp < 4
    ref = np.where(small, pndf(nm, c, sp, h[:, :2]), ndf_pdf(gm, c, sp, h[:, :2]))
    ref = ref * h[:, 2] / (4 * np.sum(wo * h, -1))
    np.testing.assert_allclose(pdf[ok], ref[ok], rtol=1e-5)
    assert ok[small].mean() > 0.9 and ok[~small].mean() > 0.9
