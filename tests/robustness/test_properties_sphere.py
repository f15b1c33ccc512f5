"""Property-based tests of prefilter.sphere: warps, frames, the chi-square test."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.sphere import (
    chi2_sphere,
    cosine_hemisphere,
    cosine_hemisphere_pdf,
    frame_from_normal,
    lobe_cap,
    spherical_direction,
    to_local,
    to_world,
    uniform_sphere,
    uniform_sphere_pdf,
)

N = settings.default.max_examples

unit = st.floats(0.0, 1.0)
theta = st.one_of(st.sampled_from([0.0, np.pi / 2, np.pi]), st.floats(0.0, np.pi))
phi = st.floats(-10.0, 10.0)


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


@settings(max_examples=N)
@given(unit, unit)
@example(0.5, 0.5)  # the centre of the concentric map (0 / 0 branch)
@example(0.0, 0.0)
@example(1.0, 1.0)
def test_warps_give_unit_directions(u1, u2):
    u = np.array([u1, u2])
    c = cosine_hemisphere(u)
    s = uniform_sphere(u)
    assert np.isclose(np.linalg.norm(c), 1.0) and c[2] >= 0.0
    assert np.isclose(np.linalg.norm(s), 1.0)
    assert np.isclose(cosine_hemisphere_pdf(c), c[2] / np.pi)
    assert uniform_sphere_pdf(s) == pytest.approx(1 / (4 * np.pi))


def test_warp_densities_integrate_to_one():
    # quadrature over the sphere (closed forms: both densities integrate to 1)
    x, w = np.polynomial.legendre.leggauss(64)
    t, p = (x + 1) / 2 * np.pi, (x + 1) * np.pi
    T, P = np.meshgrid(t, p, indexing="ij")
    d = spherical_direction(T, P)
    jac = np.sin(T) * np.pi / 2 * np.pi * np.outer(w, w)
    assert np.sum(cosine_hemisphere_pdf(d) * jac) == pytest.approx(1.0, abs=1e-3)
    assert np.sum(uniform_sphere_pdf(d) * jac) == pytest.approx(1.0, abs=1e-9)


@settings(max_examples=N)
@given(theta, phi, st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5))
@example(np.pi, 0.0, 1.0, 2.0, 3.0)  # n = -z, the branch of Duff et al.
@example(np.pi - 1e-9, 0.3, 1.0, 0.0, 0.0)
def test_frames_are_orthonormal_and_invertible(t, p, x, y, z):
    n = spherical_direction(t, p)
    tt, bt = frame_from_normal(n)
    m = np.stack([tt, bt, n])
    assert np.allclose(m @ m.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(m) == pytest.approx(1.0, abs=1e-9)
    v = np.array([x, y, z])
    assert np.allclose(to_world(to_local(v, tt, bt, n), tt, bt, n), v, atol=1e-9)


def test_chi2_accepts_exact_sampler_and_rejects_wrong_one():
    rng = np.random.default_rng(3)
    w = cosine_hemisphere(rng.random((20000, 2)))
    assert chi2_sphere(w, cosine_hemisphere_pdf).passed()
    assert not chi2_sphere(uniform_sphere(rng.random((20000, 2))), cosine_hemisphere_pdf).passed()
    axis, th = lobe_cap(w)
    assert np.isclose(np.linalg.norm(axis), 1.0) and 0.0 < th <= np.pi


@pytest.mark.parametrize("u", [[np.nan, 0.5], [1.5, 0.5], [0.5], 0.5, [[-0.1, 0.2]]])
def test_warps_reject_bad_uniforms(u):
    expect_error(lambda: cosine_hemisphere(u), "u")
    expect_error(lambda: uniform_sphere(u), "u")


@pytest.mark.parametrize("w", [[np.nan, 0.0, 1.0], [0.0, 0.0, 2.0], [1.0, 0.0], [0.0, 0.0, 0.0]])
def test_direction_functions_reject_bad_vectors(w):
    expect_error(lambda: cosine_hemisphere_pdf(w), "w")
    expect_error(lambda: uniform_sphere_pdf(w), "w")
    expect_error(lambda: frame_from_normal(w), "n")


def test_spherical_direction_and_frames_reject_bad_input():
    expect_error(lambda: spherical_direction(np.nan, 0.0), "theta")
    expect_error(lambda: spherical_direction(0.0, np.inf), "phi")
    expect_error(lambda: spherical_direction([0.1, 0.2], [0.1, 0.2, 0.3]), "theta, phi")
    t, b, n = np.eye(3)
    expect_error(lambda: to_local([np.nan, 0, 0], t, b, n), "w")
    expect_error(lambda: to_world([1.0, 0.0], t, b, n), "w")
    expect_error(lambda: to_local([1.0, 0.0, 0.0], t, b, [0, 0, np.inf]), "n")


def test_chi2_rejects_bad_arguments():
    w = cosine_hemisphere(np.random.default_rng(0).random((100, 2)))
    expect_error(lambda: chi2_sphere(w[:, :2], cosine_hemisphere_pdf), "samples")
    expect_error(lambda: chi2_sphere(w * 2, cosine_hemisphere_pdf), "samples")
    expect_error(lambda: chi2_sphere(np.zeros((0, 3)), cosine_hemisphere_pdf), "samples")
    expect_error(lambda: chi2_sphere(w, cosine_hemisphere_pdf, axis=(0, 0, 0)), "axis")
    expect_error(lambda: chi2_sphere(w, cosine_hemisphere_pdf, theta_max=0.0), "theta_max")
    expect_error(lambda: chi2_sphere(w, cosine_hemisphere_pdf, res=(0, 4)), "res")
    expect_error(lambda: chi2_sphere(w, "pdf"), "pdf")
    # a density returning NaN used to give p = NaN (a silent failure); now a clear error
    expect_error(lambda: chi2_sphere(w, lambda d: np.full(d.shape[:-1], np.nan)), "pdf")
    expect_error(lambda: lobe_cap(np.full((4, 3), np.nan)), "samples")
    expect_error(lambda: lobe_cap(w, quantile=1.5), "quantile")
