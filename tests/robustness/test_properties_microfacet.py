"""Property-based tests of prefilter.microfacet: finite outputs at the edges, promised invariants,
and PrefilterError (naming the parameter) for invalid input."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.microfacet import (
    GGX,
    Beckmann,
    beckmann_lambda,
    half_vector,
    reflect,
    smith_lambda_walter,
)

N = settings.default.max_examples  # 30 in the "ci" profile, 300 in "slow"

# theta up to 89.9 deg (grazing), both ends sampled explicitly
theta_deg = st.one_of(st.sampled_from([0.0, 89.9]), st.floats(0.0, 89.9))
phi = st.floats(0.0, 2 * np.pi)
alpha = st.one_of(st.sampled_from([1e-3, 1.0]), st.floats(-3.0, 0.0).map(lambda e: 10.0**e))


def direction(t_deg, p):
    t = np.radians(t_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def expect_error(fn, name):
    """fn() raises PrefilterError whose message names ``name`` (any other exception fails)."""
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


# -- GGX -----------------------------------------------------------------------------------------


@settings(max_examples=N)
@given(theta_deg, phi, theta_deg, phi, alpha, alpha)
@example(89.9, 0.0, 89.9, np.pi, 1e-3, 0.1)  # 1:100 anisotropy, both grazing
@example(89.9, 0.3, 0.0, 0.0, 1.0, 1e-3)
def test_ggx_finite_and_consistent(to, po, ti, pi_, ax, ay):
    g = GGX(ax, ay)
    wo, wi = direction(to, po), direction(ti, pi_)
    f = g.eval(wo, wi)
    for v in (g.D(half_vector(wo, wi)), g.smith_lambda(wo), g.G1(wo), g.G2(wo, wi), f,
              g.pdf_vndf(wo, half_vector(wo, wi)), g.pdf_reflect(wo, wi)):
        assert np.all(np.isfinite(v)) and np.all(v >= 0.0)
    assert 0.0 <= g.G2(wo, wi) <= g.G1(wo) <= 1.0
    # reciprocity of the BRDF f = eval / wi_z (Walter et al. 2007, symmetric D G2 / (4 wo_z wi_z))
    f_rev = g.eval(wi, wo)
    assert np.isclose(f * wo[2], f_rev * wi[2], rtol=1e-9, atol=1e-300)
    # the VNDF reflection density times G2/G1 is the cosine-weighted BRDF (Heitz 2014 eq. 16)
    g1 = g.G1(wo)
    assert np.isclose(g.pdf_reflect(wo, wi) * g.G2(wo, wi) / g1, f, rtol=1e-9, atol=1e-300)


@settings(max_examples=N)
@given(theta_deg, phi, alpha, alpha, st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example(89.9, 0.0, 1e-3, 0.1, 0.0, 0.0)
@example(89.9, 0.0, 1.0, 0.01, 1.0, 1.0)
@example(0.0, 0.0, 1e-3, 1e-3, 1.0, 0.5)
def test_ggx_vndf_samples_are_visible_normals(t, p, ax, ay, u1, u2):
    g = GGX(ax, ay)
    wo = direction(t, p)
    m = g.sample_vndf(wo, np.array([u1, u2]))
    assert np.all(np.isfinite(m)) and np.isclose(np.linalg.norm(m), 1.0)
    assert m[2] > 0.0
    assert m @ wo >= -1e-9  # visible normals face the viewer
    assert np.isfinite(g.pdf_vndf(wo, m))


@settings(max_examples=N // 2)
@given(theta_deg, phi, alpha, alpha)
@example(89.9, 0.0, 1e-3, 0.1)
@example(89.9, np.pi / 2, 1.0, 1e-2)
@example(60.0, 0.7, 1.0, 1.0)
def test_ggx_albedo_at_most_one(t, p, ax, ay):
    # Fresnel 1: energy is conserved at best; alpha = 1e-3 at normal incidence is a mirror (1)
    a = GGX(ax, ay).albedo(direction(t, p))
    assert np.isfinite(a) and 0.0 <= a <= 1.0 + 1e-6


def test_ggx_albedo_mirror_limit():
    # closed form: a near-mirror reflects everything (G2/G1 -> 1) away from the horizon
    assert np.isclose(GGX(1e-3).albedo(direction(45.0, 0.3)), 1.0, atol=1e-3)


def test_ggx_sample_lobe_pdf_matches_eval_over_albedo():
    # Monte Carlo vs quadrature: the lobe samples' mean wi_z equals the quadrature of
    # wi_z eval / albedo, and the quadrature of eval equals albedo()
    g = GGX(0.3, 0.05)
    wo = direction(70.0, 0.4)
    wi = g.sample_lobe(wo, 40000, np.random.default_rng(1))
    x, w = np.polynomial.legendre.leggauss(200)
    th = (x + 1) / 2 * (np.pi / 2)
    ph = (x + 1) / 2 * (2 * np.pi)
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    jac = np.sin(T) * (np.pi / 4) * np.pi * np.outer(w, w)
    f = g.eval(wo, d)
    alb = np.sum(f * jac)
    assert np.isclose(alb, g.albedo(wo), rtol=2e-2)
    mean_z = np.sum(f * d[..., 2] * jac) / alb
    assert abs(wi[:, 2].mean() - mean_z) < 5 * wi[:, 2].std() / np.sqrt(len(wi))


# -- Beckmann ------------------------------------------------------------------------------------

mean_slope = st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0))


@st.composite
def covariance(draw):
    sx = draw(alpha) / np.sqrt(2)
    sy = draw(alpha) / np.sqrt(2)
    rho = draw(st.floats(-0.95, 0.95))
    return np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])


@settings(max_examples=N)
@given(theta_deg, phi, theta_deg, phi, mean_slope, covariance())
@example(89.9, 0.0, 89.9, np.pi, (0.0, 0.0), np.diag([0.5e-6, 0.5e-2]))
@example(89.9, 0.0, 10.0, 0.0, (2.0, 0.0), np.diag([0.5, 0.5]))  # mean surface faces away
def test_beckmann_finite_and_consistent(to, po, ti, pi_, mu, cov):
    b = Beckmann(mu, cov)
    wo, wi = direction(to, po), direction(ti, pi_)
    h = half_vector(wo, wi)
    f = b.eval(wo, wi)
    for v in (b.D(h), b.G1(wo), b.G2(wo, wi), f, b.pdf_vndf(wo, h), b.pdf_reflect(wo, wi),
              b.projected_area(wo)):
        assert np.all(np.isfinite(v)) and np.all(v >= 0.0)
    assert 0.0 <= b.G2(wo, wi) <= b.G1(wo) <= 1.0
    lam = b.smith_lambda(wo)
    assert not np.isnan(lam) and lam >= 0.0


@settings(max_examples=N)
@given(theta_deg, phi, mean_slope, covariance(), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example(89.9, 0.0, (0.0, 0.0), np.diag([0.5e-6, 0.5e-2]), 1.0, 1.0)
@example(89.9, 0.0, (0.0, 0.0), np.diag([0.5e-6, 0.5e-2]), 0.0, 0.0)
def test_beckmann_vndf_samples_finite(t, p, mu, cov, u1, u2):
    b = Beckmann(mu, cov)
    wo = direction(t, p)
    m = b.sample_vndf(wo, np.array([u1, u2]))
    assert np.all(np.isfinite(m)) and np.isclose(np.linalg.norm(m), 1.0)


@settings(max_examples=N // 3)
@given(theta_deg, phi, mean_slope, covariance())
@example(89.9, 0.0, (0.0, 0.0), np.diag([0.5e-6, 0.5e-2]))
@example(89.9, 0.0, (-2.0, 0.0), np.diag([0.5, 0.5e-6]))
def test_beckmann_albedo_at_most_one(t, p, mu, cov):
    a = Beckmann(mu, cov).albedo(direction(t, p))
    assert np.isfinite(a) and 0.0 <= a <= 1.0 + 1e-4


@settings(max_examples=N)
@given(st.one_of(st.floats(-1e3, 1e3), st.sampled_from([0.0, -0.0, np.inf, -np.inf, 1e-300])))
def test_lambda_functions_never_nan(a):
    for lam in (beckmann_lambda(a), smith_lambda_walter(a)):
        assert not np.isnan(lam) and lam >= 0.0
    # Smith's Lambda decreases with a = cot(theta) / (sqrt 2 sigma) (closed-form derivative < 0)
    if 0.0 < a < 1e3:
        assert beckmann_lambda(a * 1.01) <= beckmann_lambda(a)


@settings(max_examples=N)
@given(theta_deg, phi, theta_deg, phi)
def test_reflect_is_a_mirror(t1, p1, t2, p2):
    wo, m = direction(t1, p1), direction(t2, p2)
    wi = reflect(wo, m)
    assert np.isclose(np.linalg.norm(wi), 1.0) and np.isclose(wi @ m, wo @ m)
    h = half_vector(wo, wi)
    assert np.all(np.isfinite(h))


# -- invalid input -------------------------------------------------------------------------------

BAD_ALPHA = [np.nan, np.inf, -0.1, 0.0, "rough", -np.inf]


@pytest.mark.parametrize("bad", BAD_ALPHA)
def test_ggx_rejects_bad_roughness(bad):
    expect_error(lambda: GGX(bad), "alpha_x")
    expect_error(lambda: GGX(0.5, bad), "alpha_y")
    expect_error(lambda: Beckmann.isotropic(bad), "alpha")


BAD_DIRS = {
    "nan": [np.nan, 0.0, 1.0],
    "inf": [0.0, np.inf, 1.0],
    "not unit": [0.0, 0.0, 2.0],
    "zero": [0.0, 0.0, 0.0],
    "2 components": [0.0, 1.0],
    "scalar": 1.0,
}


@pytest.mark.parametrize("bad", list(BAD_DIRS.values()), ids=list(BAD_DIRS))
@pytest.mark.parametrize("model", [GGX(0.3, 0.1), Beckmann((0.1, 0.0), np.diag([0.1, 0.2]))],
                         ids=["ggx", "beckmann"])
def test_models_reject_bad_directions(model, bad):
    good = np.array([0.0, 0.0, 1.0])
    expect_error(lambda: model.eval(bad, good), "wo")
    expect_error(lambda: model.eval(good, bad), "wi")
    expect_error(lambda: model.G1(bad), "w")
    expect_error(lambda: model.D(bad), "m")
    expect_error(lambda: model.pdf_vndf(bad, good), "wo")
    expect_error(lambda: model.pdf_reflect(good, bad), "wi")
    expect_error(lambda: model.sample_vndf(bad, [0.5, 0.5]), "wo")
    expect_error(lambda: model.albedo(bad), "wo")
    expect_error(lambda: model.smith_lambda(bad), "w")
    expect_error(lambda: model.sample_lobe(bad, 10, 0), "wo")


@pytest.mark.parametrize("u", [[0.5], [np.nan, 0.5], [1.5, 0.5], [-0.1, 0.2]])
def test_sample_vndf_rejects_bad_uniforms(u):
    expect_error(lambda: GGX(0.3).sample_vndf([0.0, 0.0, 1.0], u), "u")
    expect_error(lambda: Beckmann.isotropic(0.3).sample_vndf([0.0, 0.0, 1.0], u), "u")


def test_sample_lobe_rejects_below_horizon_and_bad_counts():
    g = GGX(0.3)
    expect_error(lambda: g.sample_lobe([0.0, 0.6, -0.8], 10, 0), "wo")
    expect_error(lambda: g.sample_lobe([0.0, 0.0, 1.0], 0, 0), "n")
    expect_error(lambda: g.sample_lobe([0.0, 0.0, 1.0], 2.5, 0), "n")
    expect_error(lambda: g.sample_lobe([0.0, 0.0, 1.0], 10, None), "rng")


@pytest.mark.parametrize("cov", [np.diag([-0.1, 0.1]), np.zeros((2, 2)), [[0.1, 0.2], [0.0, 0.1]],
                                 np.full((2, 2), np.nan), np.eye(3), [[0.1, 0.1], [0.1, 0.1]]])
def test_beckmann_rejects_bad_covariance(cov):
    expect_error(lambda: Beckmann((0.0, 0.0), cov), "slope_cov")


@pytest.mark.parametrize("mu", [(np.nan, 0.0), (0.0,), (0.0, 0.0, 0.0), "x", (np.inf, 1.0)])
def test_beckmann_rejects_bad_mean(mu):
    expect_error(lambda: Beckmann(mu, np.eye(2) * 0.1), "mean_slope")


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 1.0], [0.0, 0.0, 3.0], [1.0, 0.0]])
@pytest.mark.parametrize("model", [GGX(0.3, 0.1), Beckmann((0.1, 0.0), np.diag([0.1, 0.2]))],
                         ids=["ggx", "beckmann"])
def test_projected_areas_reject_bad_directions(model, bad):
    # were unchecked: NaN in, NaN out (GGX.smith_lambda, projected_area, mean_projected_area)
    expect_error(lambda: model.smith_lambda(bad), "w")
    expect_error(lambda: model.projected_area(bad), "w")
    expect_error(lambda: model.mean_projected_area(bad), "w")


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 1.0], [1.0, 0.0], 2.0])
def test_reflect_half_vector_reject_bad_vectors(bad):
    expect_error(lambda: reflect(bad, [0.0, 0.0, 1.0]), "wo")
    expect_error(lambda: reflect([0.0, 0.0, 1.0], bad), "m")
    expect_error(lambda: half_vector(bad, [0.0, 0.0, 1.0]), "wo")
    expect_error(lambda: half_vector([0.0, 0.0, 1.0], bad), "wi")


@settings(max_examples=N // 3)
@given(theta_deg, phi, mean_slope, covariance(), st.integers(0, 2**31))
@example(89.9, 0.0, (0.0017, 0.0), np.diag([1e-10, 1e-10]), 0)  # albedo 0, G1 > 0: looped forever
def test_beckmann_sample_lobe_terminates(t, p, mu, cov, seed):
    b = Beckmann(mu, cov)
    wo = direction(t, p)
    try:
        wi = b.sample_lobe(wo, 16, seed)
    except PrefilterError as err:  # an empty lobe is refused, naming the view
        assert "wo" in str(err)
        assert b.albedo(wo) * 1e9 < 16 or b.G1(wo) == 0.0
        return
    assert wi.shape == (16, 3) and np.allclose(np.linalg.norm(wi, axis=-1), 1.0)
    assert np.all(wi[:, 2] > 0.0)


@pytest.mark.parametrize("model", [GGX(0.3), Beckmann.isotropic(0.3)], ids=["ggx", "beckmann"])
def test_sample_lobe_rejects_negative_seeds(model):
    # was NumPy's "expected non-negative integer" ValueError
    expect_error(lambda: model.sample_lobe([0.0, 0.0, 1.0], 4, -3), "rng")
