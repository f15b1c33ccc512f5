"""Deterministic area-light references (prefilter.glints.reference) against pointwise P-NDF
values, closed forms and plain Monte Carlo of the glint BRDF."""

import numpy as np
import pytest
from maps import normals_from_s, sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints import reference as ref
from prefilter.glints.brdf import glint_brdf_cos, surface
from prefilter.glints.pndf import pndf
from prefilter.render.lights import QuadLight, sample_quad_area

NM = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)
SR = 0.01


@pytest.fixture(scope="module")
def surf():
    return surface(None, NM, intrinsic_roughness=SR)


def test_pndf_multi_equals_pointwise_pndf(surf):
    """Every point of every footprint (tiny, medium, wider than the map) equals pndf."""
    rng = np.random.default_rng(0)
    N = 12
    c = rng.uniform(-10, 70, (N, 2))
    sp = np.concatenate([[0.0, 0.3], rng.uniform(1, 30, N - 3), [90.0]])
    cnt = rng.integers(0, 40, N)
    cnt[3] = 0
    off = np.concatenate([[0], np.cumsum(cnt)])
    s = rng.uniform(-0.35, 0.35, (off[-1], 2))
    own = np.repeat(np.arange(N), cnt)
    got = ref.pndf_multi(surf, c, sp, s, off)
    want = pndf(NM, c[own], sp[own], s, SR)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * want.max())
    assert want.max() > 1.0  # points hit glints
    with pytest.raises(PrefilterError, match="offsets"):
        ref.pndf_multi(surf, c, sp, s, off[::-1])


def _gauss_table(lo, h, R, a, tau):
    g = lo + h * np.arange(R)
    X, Y = np.meshgrid(g, g)
    return np.exp(-((X - a[0]) ** 2 + (Y - a[1]) ** 2) / (2 * tau**2))


def test_pndf_integral_flat_map_closed_form():
    """A tilted flat map: D is N(n, sr^2 I); against a Gaussian bump T the integral is the
    Gaussian product's closed form (tabulated T: bilinear error O(h^2); T three element stds
    wide, the regime of the rule: 3-point Gauss-Hermite is exact to degree 5)."""
    n0 = np.array([0.1, -0.05])
    nm = normals_from_s(np.full((16, 16), n0[0]), np.full((16, 16), n0[1]))
    s = surface(None, nm, intrinsic_roughness=0.02)
    lo, R = -0.5, 401
    h = 1.0 / (R - 1)
    a, tau = np.array([0.13, -0.02]), 0.06
    T = _gauss_table(lo, h, R, a, tau)[None, ..., None]
    got = ref.pndf_integral(s, [[3.0, 4.0]], [2.0], T, lo, h)[0, 0]
    v = 0.02**2 + tau**2
    want = tau**2 / v * np.exp(-np.sum((a - n0) ** 2) / (2 * v))
    assert abs(got - want) < 1e-3 * want, (got, want)


@pytest.mark.parametrize("sp", [0.0, 3.0, pytest.param(8.0, marks=pytest.mark.slow)])
def test_pndf_integral_matches_grid_sum_of_pndf(surf, sp):
    """Sinusoid map (wide, sheared elements): the element cubature agrees with a fine Riemann
    sum of pointwise pndf values times the same smooth T (its exact node values)."""
    lo, R = -0.6, 121
    h = 1.2 / (R - 1)
    a, tau = np.array([0.1, 0.05]), 0.12
    c = np.array([[20.3, 11.7]])
    T = _gauss_table(lo, h, R, a, tau)
    got = ref.pndf_integral(surf, c, [sp], T[None, ..., None], lo, h)[0, 0]
    g = np.linspace(-0.6, 0.6, 241)  # spacing sr / 2
    X, Y = np.meshgrid(g, g)
    D = pndf(NM, c, sp, np.stack([X, Y], -1), SR)
    Tf = np.exp(-((X - a[0]) ** 2 + (Y - a[1]) ** 2) / (2 * tau**2))
    dg = g[1] - g[0]
    want = np.sum(D * Tf) * dg * dg
    assert abs(got - want) < 5e-3 * want, (got, want)


def facing_quad(wo, size, dist):
    ctr = np.array([-wo[0], -wo[1], wo[2]]) * dist
    nrm = -ctr / np.linalg.norm(ctr)
    a = np.cross(nrm, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(nrm, a)
    V = np.stack([ctr - size * a - size * b, ctr + size * a - size * b,
                  ctr + size * a + size * b, ctr - size * a + size * b])
    if np.dot(np.cross(V[1] - V[0], V[2] - V[0]), nrm) < 0:
        V = V[::-1].copy()
    return QuadLight(V, [1.0, 1.0, 1.0])


@pytest.mark.parametrize("sp, size, tilt", [(1.5, 0.2, 0.2), (5.0, 0.3, 0.5)])
def test_quad_integral_matches_monte_carlo(surf, sp, size, tilt):
    """Against plain Monte Carlo (uniform area samples) of the direct glint BRDF over the quad:
    within 3 sigma, sigma < 2 %."""
    wo = np.array([np.sin(tilt), 0.1, np.cos(tilt)])
    wo /= np.linalg.norm(wo)
    light = facing_quad(wo, size, 3.0)
    c = np.array([[17.3, 40.1]])
    got = ref.quad_integral(surf, c, [sp], wo[None], light.vertices[None], light.radiance, 0.9)
    rng = np.random.default_rng(3)
    n = 60000
    y = sample_quad_area(light.vertices, rng.random((n, 2)))
    d2 = np.sum(y * y, -1)
    wi = y / np.sqrt(d2)[:, None]
    f = glint_brdf_cos(surf, c, sp, wo, wi, 0.9)[:, 0] * light.area * np.maximum(
        -(wi @ light.normal), 0.0) / d2
    mc, err = f.mean(), f.std() / np.sqrt(n)
    assert err < 0.02 * mc
    assert abs(got[0, 0] - mc) <= 3 * err, (got[0, 0], mc, err)


def _sg_setup():
    mu = np.array([[3.0, 2.0, 1.0], [0.5, 0.5, 0.8]])
    lam = np.array([40.0, 8.0])
    p = np.array([[-0.45, -0.1, 0.89], [0.3, 0.5, 0.81]])
    return mu, lam, p / np.linalg.norm(p, axis=-1, keepdims=True)


def _wo_env():
    wo = np.array([0.4, 0.1, 0.9])
    return wo / np.linalg.norm(wo)


def test_environment_integral_matches_monte_carlo(surf):
    """Against the unbiased SG-sampling estimator (shade_sg without prefiltering, 64k samples):
    within 3 sigma for two footprints."""
    from prefilter.glints.envlight import shade_sg

    mu, lam, p = _sg_setup()
    wo = _wo_env()
    c = np.array([[17.3, 40.1], [5.5, 9.0]])
    sp = np.array([3.0, 8.0])
    got = ref.environment_integral(surf, c, sp, np.tile(wo, (2, 1)), mu, lam, p, 0.9)
    M, n = 128, 128
    est = shade_sg(surf, np.repeat(c, M, 0), np.repeat(sp, M), np.tile(wo, (2 * M, 1)), mu, lam,
                   p, 0.9, n_samples=n, rng=4, prefilter=False).reshape(2, M, 3)
    mc, err = est.mean(1), est.std(1) / np.sqrt(M)
    assert np.all(err < 0.03 * mc)
    assert np.all(np.abs(got - mc) <= 3 * err), (got, mc, err)


def test_environment_blur_is_the_prefiltered_expectation():
    """``blur=r``: the expectation of the estimator with D(h) replaced by its mean over
    h_xy +- r. Tilted flat map (D = N(n0, sr^2 I), box means in closed form by erf), Monte Carlo
    of that estimator with SG samples; the blur is visible at the test's tolerance."""
    from scipy.special import ndtr

    from prefilter.glints.brdf import vcavity_g2
    from prefilter.microfacet.fresnel import schlick
    from prefilter.glints.envlight import sample_sg

    mu, lam, p = _sg_setup()
    wo = _wo_env()
    n0, sr, r = np.array([0.05, 0.02]), 0.01, 0.06
    nm = normals_from_s(np.full((16, 16), n0[0]), np.full((16, 16), n0[1]))
    s = surface(None, nm, intrinsic_roughness=sr)
    c = np.array([[3.0, 4.0]])
    got = ref.environment_integral(s, c, [2.0], wo[None], mu, lam, p, 0.9, blur=[r])[0]
    plain = ref.environment_integral(s, c, [2.0], wo[None], mu, lam, p, 0.9)[0]
    rng = np.random.default_rng(5)
    n = 100000
    wi, pdf = sample_sg(mu, lam, p, rng.random((n, 3)))
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    box = np.prod(ndtr((h[:, :2] + r - n0) / sr) - ndtr((h[:, :2] - r - n0) / sr), -1)
    Dbar = box / (2 * r) ** 2
    ok = (wi[:, 2] > 0) & (h[:, 2] > 0)
    L = np.exp(lam * (wi @ p.T - 1.0)) @ mu
    f = (np.where(ok, Dbar * vcavity_g2(wo, wi, h) / (4 * wo[2] * pdf), 0.0)[:, None]
         * schlick(0.9, np.sum(wi * h, -1)[:, None]) * L)
    mc, err = f.mean(0), f.std(0) / np.sqrt(n)
    assert np.all(err < 0.01 * mc)
    assert np.all(np.abs(got - mc) <= 3 * err), (got, mc, err)
    assert np.all(np.abs(got - plain) > 6 * err), (got, plain, err)


def test_validation(surf):
    with pytest.raises(PrefilterError, match="corners"):
        ref.quad_integral(surf, [[1.0, 1.0]], [2.0], [[0, 0, 1.0]], np.zeros((1, 3, 3)),
                          [1, 1, 1])
    with pytest.raises(PrefilterError, match="GlintSurface|normal map"):
        from prefilter.glints import reference

        reference.pndf_multi(object(), [[1.0, 1.0]], [2.0], [[0.0, 0.0]], [0, 1])
