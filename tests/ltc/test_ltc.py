"""The LTC distribution: closed forms, normalisation by quadrature, chi-square tests of sampling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from prefilter.errors import PrefilterError
from prefilter.ltc import LTC
from prefilter.ltc.ltc import as_ltc_matrix
from prefilter.sphere import chi2_sphere, lobe_cap, spherical_direction, uniform_sphere

MATRICES = {
    "identity": np.eye(3),
    "isotropic_ggx_like": np.array([[0.4, 0.0, 0.3], [0.0, 0.45, 0.0], [-0.1, 0.0, 1.0]]),
    "anisotropic": np.array([[0.8, 0.3, -0.2], [0.1, 0.25, 0.4], [0.2, -0.1, 1.0]]),
    "narrow": np.diag([0.04, 0.06, 1.0]) @ np.array([[1, 0, 0.2], [0, 1, 0], [0, 0, 1.0]]),
    "mirrored": np.array([[-0.6, 0.1, 0.3], [0.2, 0.9, 0.0], [0.1, 0.2, 1.0]]),
}


def sphere_quadrature(f, axis=(0.0, 0.0, 1.0), theta_max=np.pi, n_theta=400, n_phi=300):
    """Gauss-Legendre in (cos theta, phi) over the cap of ``theta_max`` around ``axis``."""
    from prefilter.sphere import frame_from_normal, to_world

    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t, b = frame_from_normal(axis)
    x, wx = np.polynomial.legendre.leggauss(n_theta)
    y, wy = np.polynomial.legendre.leggauss(n_phi)
    cmin = np.cos(theta_max)
    c = cmin + (1 - cmin) * (x + 1) / 2
    p = np.pi * (y + 1)
    w = np.outer(wx * (1 - cmin) / 2, wy * np.pi)
    s = np.sqrt(1 - c * c)
    loc = np.stack(np.broadcast_arrays(s[:, None] * np.cos(p), s[:, None] * np.sin(p),
                                       c[:, None]), axis=-1)
    return float(np.sum(f(to_world(loc, t, b, axis)) * w))


def test_identity_is_the_clamped_cosine():
    rng = np.random.default_rng(0)
    w = uniform_sphere(rng.random((1000, 2)))
    ltc = LTC(np.eye(3))
    np.testing.assert_allclose(ltc.eval(w), np.maximum(0, w[:, 2]) / np.pi, atol=1e-15)
    np.testing.assert_array_equal(ltc.pdf(w), ltc.eval(w))


def test_scaled_rotation_is_a_rotated_cosine():
    # D for M = s R is the cosine about R z (scale invariance of the normalised transform)
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q if np.linalg.det(q) > 0 else -q
    w = uniform_sphere(rng.random((1000, 2)))
    got = LTC(3.7 * R).eval(w)
    np.testing.assert_allclose(got, np.maximum(0, w @ R[:, 2]) / np.pi, atol=1e-13)


@pytest.mark.parametrize("name", sorted(MATRICES))
def test_eval_integrates_to_one(name):
    # the kink of max(0, .) along a great circle limits Gauss-Legendre to ~1e-5 here
    assert sphere_quadrature(LTC(MATRICES[name]).eval) == pytest.approx(1.0, abs=1e-4)


def test_narrow_eval_integrates_to_one_on_a_cap_grid():
    M = MATRICES["narrow"]
    ltc = LTC(M)
    axis = M[:, 2] / np.linalg.norm(M[:, 2])
    inner = sphere_quadrature(ltc.eval, axis, theta_max=0.8, n_theta=800, n_phi=200)
    outer = sphere_quadrature(lambda w: ltc.eval(w) * (w @ axis < np.cos(0.8)))
    assert inner + outer == pytest.approx(1.0, abs=1e-4)


def test_eval_integrates_to_one_monte_carlo():
    # uniform directions: mean of 4 pi D(w) estimates 1, with its standard error
    rng = np.random.default_rng(2)
    M = MATRICES["anisotropic"]
    f = 4 * np.pi * LTC(M).eval(uniform_sphere(rng.random((1_000_000, 2))))
    assert abs(f.mean() - 1.0) < 5 * f.std() / 1e3


@pytest.mark.parametrize("name", sorted(MATRICES))
def test_sample_passes_chi_square(name):
    ltc = LTC(MATRICES[name])
    pilot = ltc.sample(np.random.default_rng(10).random((20000, 2)))
    # heavy-tailed narrow lobe: a 99.5 % cap puts most of the peak in the first ring; a 90 % cap
    # keeps the rings finer than the peak, so the test resolves its shape
    axis, theta_max = lobe_cap(pilot, quantile=0.9 if name == "narrow" else 0.995)
    samples = ltc.sample(np.random.default_rng(11).random((200_000, 2)))
    res = chi2_sphere(samples, ltc.pdf, axis=axis, theta_max=theta_max, res=(12, 24))
    assert res.passed(0.01), res


def test_chi_square_rejects_a_wrong_density():
    # the test must be able to fail: samples of one LTC against another's density
    a, b = LTC(MATRICES["isotropic_ggx_like"]), LTC(MATRICES["anisotropic"])
    samples = a.sample(np.random.default_rng(12).random((200_000, 2)))
    axis, theta_max = lobe_cap(a.sample(np.random.default_rng(13).random((20000, 2))))
    assert not chi2_sphere(samples, b.pdf, axis=axis, theta_max=theta_max).passed(0.01)


def test_mean_cosine_of_isotropic_scaling_matches_closed_form():
    # M = diag(a, a, 1): E[w_z] = 2 int_0^1 u^2 / sqrt(a^2 (1 - u^2) + u^2) du (equations.md 4)
    a = 0.3
    ltc = LTC(np.diag([a, a, 1.0]))
    closed = 2 * integrate.quad(lambda u: u * u / np.sqrt(a * a * (1 - u * u) + u * u), 0, 1)[0]
    z = ltc.sample(np.random.default_rng(14).random((1_000_000, 2)))[:, 2]
    assert abs(z.mean() - closed) < 5 * z.std() / 1e3
    assert sphere_quadrature(lambda w: ltc.eval(w) * w[..., 2]) == pytest.approx(
        closed, abs=1e-6)


def test_samples_are_unit_and_on_the_support():
    ltc = LTC(MATRICES["anisotropic"])
    w = ltc.sample(np.random.default_rng(15).random((10000, 2)))
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-12)
    assert np.all(ltc.eval(w) > 0)


def test_batched_matrices_broadcast():
    M = np.stack([MATRICES["identity"], MATRICES["anisotropic"]])
    ltc = LTC(M)
    w = spherical_direction(0.3, 0.5)
    got = ltc.eval(w)
    assert got.shape == (2,)
    assert got[0] == pytest.approx(np.cos(0.3) / np.pi)
    u = np.random.default_rng(16).random((5, 2, 2))
    assert ltc.sample(u).shape == (5, 2, 3)


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: LTC(np.ones((3, 3))), "invertible"),
        (lambda: LTC(np.ones((3, 2))), r"\(\.\.\., 3, 3\)"),
        (lambda: LTC(np.full((3, 3), np.nan)), "finite"),
        (lambda: as_ltc_matrix(np.diag([1.0, 1e-10, 1.0])), "condition"),
        (lambda: LTC(np.eye(3)).eval([0.0, 0.0, 2.0]), "unit vectors"),
        (lambda: LTC(np.eye(3)).sample([0.5, 1.5]), r"\[0, 1\]"),
        (lambda: LTC(np.eye(3)).sample([0.5, 0.5, 0.5]), r"\(\.\.\., 2\)"),
    ],
)
def test_validation(call, match):
    with pytest.raises(PrefilterError, match=match):
        call()
