"""Non-centred anisotropic Beckmann: closed forms, Smith integrals, quadrature identities, VNDF."""

import numpy as np
import pytest
from mf_quad import direction, hemisphere_integral, normal_from_slope, slope_jacobian_fd
from scipy import integrate, special

from prefilter.errors import PrefilterError
from prefilter.microfacet import Beckmann, beckmann_lambda, reflect, smith_lambda_walter
from prefilter.microfacet.beckmann import _sample_ramp
from prefilter.sphere import chi2_sphere, chi2_warped, lobe_cap, slope_warp

# Measured on a uniform grid of 2e6 points over a in (0, 10] (docs/microfacet.md).
WALTER_MAX_REL = 1.0326  # at a = 1.593, where the fit crosses zero (exact Lambda ~ 2e-3)
WALTER_MAX_ABS_FROM_0_1 = 9.551e-3  # over [0.1, 10]; the error grows like 8e-4 / a as a -> 0
WALTER_MAX_REL_BELOW_1 = 4.614e-2  # over (0, 1]
WALTER_MAX_G1_ABS = 3.109e-3  # |1/(1+fit) - 1/(1+exact)| over (0, 10]

# name: (model, quadrature width, quadrature grid)
MODELS = {
    "iso-0.02": (Beckmann.isotropic(0.02), 0.01, (200, 256)),
    "iso-1": (Beckmann.isotropic(1.0), 0.5, (200, 256)),
    "aniso-1:20-mean": (Beckmann.anisotropic(0.02, 0.4, (0.3, -0.2)), 0.01, (400, 1024)),
    "correlated-mean": (Beckmann([0.5, 0.3], [[0.02, 0.015], [0.015, 0.03]]), 0.05, (200, 256)),
}


def _mean_area(b, w):
    return w[..., 2] - w[..., :2] @ b.mean_slope


def test_isotropic_closed_form():
    # Walter et al. 2007 eq. 25: exp(-tan^2 / a^2) / (pi a^2 cos^4)
    a = 0.35
    th = np.radians(np.linspace(0, 80, 9))
    m = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    ref = np.exp(-np.tan(th) ** 2 / a**2) / (np.pi * a**2 * np.cos(th) ** 4)
    np.testing.assert_allclose(Beckmann.isotropic(a).D(m), ref, rtol=1e-13)


def test_d_matches_gaussian_slopes_via_finite_difference_jacobian():
    mu, cov = np.array([0.2, -0.4]), np.array([[0.09, -0.03], [-0.03, 0.04]])
    s = np.random.default_rng(0).multivariate_normal(mu, cov, size=300)
    dev = s - mu
    q = np.einsum("ni,ij,nj->n", dev, np.linalg.inv(cov), dev)
    ref = np.exp(-q / 2) / (2 * np.pi * np.sqrt(np.linalg.det(cov)))
    m = normal_from_slope(s)
    d = Beckmann(mu, cov).D(m)
    np.testing.assert_allclose(d * m[:, 2] * slope_jacobian_fd(s), ref, rtol=1e-7)


@pytest.mark.parametrize("name", MODELS)
def test_ndf_normalised(name):
    b, width, (npol, naz) = MODELS[name]
    val = hemisphere_integral(lambda m: b.D(m) * m[..., 2], width=width, n_polar=npol,
                              n_azimuth=naz)
    assert val == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("name, theta, phi", [
    ("iso-1", 0, 0), ("iso-0.02", 89, 150), ("aniso-1:20-mean", 80, 200),
    ("correlated-mean", 45, 30), ("correlated-mean", 80, 200)])
def test_projected_area_identity_with_mean_slope(name, theta, phi):
    _check_projected_area(name, theta, phi)


@pytest.mark.slow
@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("theta, phi", [(0, 0), (45, 30), (80, 200), (89, 150)])
def test_projected_area_identity_grid(name, theta, phi):
    _check_projected_area(name, theta, phi)


def _check_projected_area(name, theta, phi):
    # The mean surface has normal ~ (-mu, 1): integral G1 max(0, wo.m) D = wo_z - mu.wo_xy
    # (LEADR supplemental eq. 9); views below the mean surface have G1 = 0.
    b, width, (npol, naz) = MODELS[name]
    wo = direction(theta, phi)
    area = _mean_area(b, wo)
    val = hemisphere_integral(lambda m: b.G1(wo) * (m @ wo) * b.D(m), wo=wo, width=width,
                              n_polar=npol, n_azimuth=naz)
    if area <= 0:
        assert b.G1(wo) == 0.0 and val == 0.0
        return
    assert val == pytest.approx(area, rel=1e-4)
    # projected_area() is the same integral without G1, in closed form.
    raw = hemisphere_integral(lambda m: (m @ wo) * b.D(m), wo=wo, width=width,
                              n_polar=npol, n_azimuth=naz)
    assert b.projected_area(wo) == pytest.approx(raw, rel=1e-4)


def test_projected_area_below_the_mean_surface():
    b = Beckmann([0.8, 0.0], [[0.1, 0.0], [0.0, 0.05]])
    wo = direction(60, 0)  # wo_z - mu.wo_xy = 0.5 - 0.69 < 0
    assert _mean_area(b, wo) < 0 and b.G1(wo) == 0.0 and b.albedo(wo) == 0.0
    raw = hemisphere_integral(lambda m: (m @ wo) * b.D(m), wo=wo, width=0.6,
                              n_polar=800, n_azimuth=1024)
    assert raw > 0 and b.projected_area(wo) == pytest.approx(raw, rel=1e-6)
    with pytest.raises(PrefilterError, match="empty"):
        b.sample_lobe(wo, 10, 0)


@pytest.mark.parametrize("theta, phi", [(20, 0), (70, 60), (88, 70)])
def test_lambda_matches_smith_integral_with_mean_slope(theta, phi):
    # Lambda = (1/(c - mu_phi)) int_c^inf (q - c) N(q; mu_phi, s_phi^2) dq, q the slope along
    # the azimuth of w, c = cot(theta) (Smith 1967 with a shifted Gaussian; LEADR suppl. 3.2).
    mu, cov = np.array([0.1, -0.2]), np.array([[0.1, 0.03], [0.03, 0.05]])
    w = direction(theta, phi)
    u = w[:2] / np.hypot(w[0], w[1])
    m_phi, s_phi = u @ mu, np.sqrt(u @ cov @ u)
    c = w[2] / np.hypot(w[0], w[1])
    f = lambda q: (q - c) * np.exp(-0.5 * ((q - m_phi) / s_phi) ** 2) / (s_phi * np.sqrt(2 * np.pi))  # noqa: E731
    ref = integrate.quad(f, c, np.inf, epsabs=0, epsrel=1e-12, limit=200)[0] / (c - m_phi)
    assert Beckmann(mu, cov).smith_lambda(w) == pytest.approx(ref, rel=1e-9)


def test_lambda_is_stable_for_all_a():
    a = np.concatenate([[-np.inf, -1e3, -1.0, 0.0, 1e-300, 1e-12], np.geomspace(1e-6, 1e3, 400),
                        [30.0, 1e10, np.inf]])
    lam = beckmann_lambda(a)
    assert not np.any(np.isnan(lam))
    assert np.all(lam[a <= 0] == np.inf)
    fin = (a > 0) & np.isfinite(a)
    assert np.all(np.isfinite(lam[fin])) and np.all(lam[fin] >= 0)
    assert np.all(np.diff(lam[6:-3]) <= 0)  # decreasing in a
    # a -> 0+: Lambda ~ 1 / (2 a sqrt(pi)) - 1/2; large a: Lambda ~ exp(-a^2) / (4 a^3 sqrt(pi)).
    assert beckmann_lambda(1e-8) == pytest.approx(1 / (2e-8 * np.sqrt(np.pi)) - 0.5, rel=1e-12)
    for x in (8.0, 15.0, 25.0):
        asym = np.exp(-x * x) / (4 * x**3 * np.sqrt(np.pi)) * (1 - 1.5 / x**2 + 15 / (4 * x**4))
        assert beckmann_lambda(x) == pytest.approx(asym, rel=3e-4 if x == 8 else 2e-6)
    assert beckmann_lambda(np.inf) == 0.0 and beckmann_lambda(30.0) == 0.0


def test_lambda_quadrature_over_a():
    # 1 + Lambda(a) = E[max(0, t - X)] / t with X ~ N(0, 1), t = sqrt(2) a.
    for a in (0.01, 0.3, 1.0, 2.5, 5.0):
        t = np.sqrt(2) * a
        e = integrate.quad(lambda x: (t - x) * np.exp(-x * x / 2) / np.sqrt(2 * np.pi), -np.inf, t,
                           epsabs=0, epsrel=1e-13)[0]
        assert 1 + beckmann_lambda(a) == pytest.approx(e / t, rel=1e-11)


def test_walter_fit_error_bounds():
    a = np.linspace(0, 10, 2_000_001)[1:]
    exact, fit = beckmann_lambda(a), smith_lambda_walter(a)
    rel = np.abs(fit - exact) / exact
    assert rel.max() <= WALTER_MAX_REL * 1.01
    assert rel[a <= 1].max() <= WALTER_MAX_REL_BELOW_1 * 1.01
    assert np.abs(fit - exact)[a >= 0.1].max() <= WALTER_MAX_ABS_FROM_0_1 * 1.01
    g1 = np.abs(1 / (1 + fit) - 1 / (1 + exact))
    assert g1.max() <= WALTER_MAX_G1_ABS * 1.01
    # ...and the bounds are tight (the test fails if the fit were silently replaced).
    assert rel.max() > WALTER_MAX_REL * 0.99 and g1.max() > WALTER_MAX_G1_ABS * 0.99
    assert np.all(smith_lambda_walter([-1.0, 0.0]) == np.inf)


@pytest.mark.parametrize("a", [-60.0, -8.0, -1.0, 0.0, 0.7, 4.0, 50.0, 1e8])
def test_ramp_inversion_accuracy(a):
    u = np.linspace(1e-6, 1 - 1e-6, 501)
    x = _sample_ramp(np.full(u.shape, a), u)
    assert np.all(x <= a)
    if a < -30:
        # phi(a) underflows: compare the tail shape a - x ~ Gamma(2, 1/|a|) in the limit.
        r = (a - x) * abs(a)
        np.testing.assert_allclose((1 + r) * np.exp(-r), u, atol=2e-3)
        return
    # CDF (a Phi(x) + phi(x)) / (a Phi(a) + phi(a)), evaluated at high precision via log-space.
    num = a * special.ndtr(x) + np.exp(-x * x / 2) / np.sqrt(2 * np.pi)
    den = a * special.ndtr(a) + np.exp(-a * a / 2) / np.sqrt(2 * np.pi)
    dens = np.maximum(a - x, 0) * np.exp(-x * x / 2) / np.sqrt(2 * np.pi) / den
    err_x = np.abs(num / den - u) / np.maximum(dens, 1e-300)
    assert np.max(np.minimum(err_x, np.abs(num / den - u) * 1e6)) < 1e-9


def test_eval_generalised_reciprocity():
    # f_meso = eval(wo, wi) / A(wi) is symmetric, A = projected area of the mean surface.
    b = Beckmann([0.2, -0.1], [[0.05, 0.02], [0.02, 0.03]])
    rng = np.random.default_rng(3)
    w = rng.normal(size=(2, 500, 3)) * [1, 1, 0.5]
    w[..., 2] = np.abs(w[..., 2])
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    wo, wi = w
    lhs = b.eval(wo, wi) * _mean_area(b, wo)
    rhs = b.eval(wi, wo) * _mean_area(b, wi)
    np.testing.assert_allclose(lhs, rhs, rtol=1e-12, atol=1e-300)
    below = (_mean_area(b, wo) <= 0) | (_mean_area(b, wi) <= 0)
    assert below.any() and np.all(b.eval(wo, wi)[below] == 0)


def test_broadcasting_of_parameters():
    alpha = np.array([0.1, 0.4])
    b = Beckmann.isotropic(alpha[:, None])  # batch (2, 1) against directions (3,)
    w = np.stack([direction(10, 0), direction(60, 30), direction(85, 100)])
    for fn in ("D", "G1", "albedo"):
        batch = getattr(b, fn)(w)
        assert batch.shape == (2, 3)
        for i, a in enumerate(alpha):
            np.testing.assert_allclose(batch[i], getattr(Beckmann.isotropic(a), fn)(w), rtol=1e-12)


def test_validation():
    with pytest.raises(PrefilterError, match="symmetric"):
        Beckmann([0, 0], [[0.1, 0.02], [0.03, 0.1]])
    with pytest.raises(PrefilterError, match="positive definite"):
        Beckmann([0, 0], [[0.1, 0.2], [0.2, 0.1]])
    with pytest.raises(PrefilterError, match="positive definite"):
        Beckmann([0, 0], [[-0.1, 0.0], [0.0, 0.1]])
    with pytest.raises(PrefilterError, match="slope_cov"):
        Beckmann([0, 0], [0.1, 0.1])
    with pytest.raises(PrefilterError, match="mean_slope"):
        Beckmann([0, 0, 0], np.eye(2))
    with pytest.raises(PrefilterError, match="mean_slope"):
        Beckmann([np.nan, 0], np.eye(2))
    with pytest.raises(PrefilterError, match="alpha"):
        Beckmann.isotropic(0.0)


# Views: near-normal and grazing 80-89 deg; roughness 0.02..1; ratios to 1:20; mean slopes.
VNDF_FAST = [
    (Beckmann.isotropic(0.02), 0),
    (Beckmann.anisotropic(0.02, 0.4, (0.3, -0.2)), 85),
    (Beckmann([0.5, 0.3], [[0.02, 0.015], [0.015, 0.03]]), 5),
    (Beckmann([0.1, 0.0], [[0.5, 0.2], [0.2, 0.4]]), 89),
    (Beckmann([0.8, 0.0], [[0.1, 0.0], [0.0, 0.05]]), 60),  # view below the mean surface (a < 0)
]
VNDF_SLOW = [(Beckmann.anisotropic(a, a * r, mu), t) for a in (0.02, 0.2, 1.0)
             for r in (1.0, 0.05) for mu in ((0, 0), (0.3, -0.4)) for t in (0, 3, 80, 89)]


def _chi2_vndf(model, wo, n, seed):
    # Bins in the whitened slope space of the nominal parameters (see test_ggx._chi2_vndf).
    warp = slope_warp(model.mean_slope, np.linalg.cholesky(model.slope_cov), wo=wo)
    m = model.sample_vndf(wo, np.random.default_rng(seed).random((n, 2)))
    return chi2_warped(m, lambda w: model.pdf_vndf(wo, w), warp)


@pytest.mark.parametrize("case", range(len(VNDF_FAST)))
def test_vndf_chi2(case):
    model, theta = VNDF_FAST[case]
    res = _chi2_vndf(model, direction(theta, 30 if theta else 0), 200_000, 5)
    assert res.passed(), res


@pytest.mark.slow
@pytest.mark.parametrize("case", range(len(VNDF_SLOW)))
def test_vndf_chi2_grid(case):
    model, theta = VNDF_SLOW[case]
    res = _chi2_vndf(model, direction(theta, 130), 1_000_000, 9)
    assert res.passed(), res


def test_chi2_rejects_covariance_10_percent_off():
    wo = direction(70, 20)
    good = Beckmann([0.1, 0.2], [[0.05, 0.01], [0.01, 0.02]])
    bad = Beckmann([0.1, 0.2], [[0.055, 0.011], [0.011, 0.022]])
    axis, th = lobe_cap(good.sample_vndf(wo, np.random.default_rng(1).random((20_000, 2))))
    m = bad.sample_vndf(wo, np.random.default_rng(2).random((200_000, 2)))
    res = chi2_sphere(m, lambda w: good.pdf_vndf(wo, w), axis=axis, theta_max=th)
    assert res.p_value < 1e-6


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("theta", [30, 85])
def test_albedo_quadrature_vs_monte_carlo(name, theta):
    b = MODELS[name][0]
    wo = direction(theta, 200)
    m = b.sample_vndf(wo, np.random.default_rng(4).random((200_000, 2)))
    wi = reflect(wo, m)
    pdf = b.pdf_reflect(wo, wi)
    est = np.where(pdf > 0, b.eval(wo, wi) / np.maximum(pdf, 1e-300), 0.0)
    se = est.std() / np.sqrt(len(est))
    assert abs(b.albedo(wo) - est.mean()) < 4 * se + 1e-6
    assert b.albedo(wo) <= 1.0


@pytest.mark.parametrize("name, thetas", [("correlated-mean", (40, 80)), ("iso-1", (80,))])
def test_albedo_vs_direct_quadrature_of_eval(name, thetas):
    b = MODELS[name][0]
    for theta in thetas:
        wo = direction(theta, 200)
        ref = hemisphere_integral(lambda w: b.eval(wo, w), width=0.3, n_polar=300, n_azimuth=512)
        assert b.albedo(wo) == pytest.approx(ref, abs=1e-5)
