"""Property-based tests of prefilter.leadr (moment maps and shading): grazing views, lights on
and below the horizon, narrow and extremely anisotropic slope distributions."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.leadr import (
    EnvMap,
    artificial_micronormal,
    diffuse_directional,
    diffuse_sh,
    env_specular,
    gaussian_grid,
    grid_normals,
    moments,
    point_light,
    procedural_env,
    schlick,
    shading_stats,
    slopes_from_height,
    slopes_from_normals,
    stats_to_moments,
)
from prefilter.microfacet import Beckmann

N = settings.default.max_examples

theta_deg = st.one_of(st.sampled_from([0.0, 89.9, 90.0]), st.floats(0.0, 90.0))
below_deg = st.one_of(st.sampled_from([90.0, 135.0, 180.0]), st.floats(0.0, 180.0))
phi = st.floats(0.0, 2 * np.pi)
mean_slope = st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))


def direction(t_deg, p):
    t = np.radians(t_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@st.composite
def covariance(draw):
    # slope std from 1e-3 (a mirror) to 3 (very rough), anisotropy up to 1:3000
    sx = 10.0 ** draw(st.floats(-3.0, 0.5))
    sy = 10.0 ** draw(st.floats(-3.0, 0.5))
    rho = draw(st.floats(-0.99, 0.99))
    return np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


@settings(max_examples=N)
@given(theta_deg, phi, below_deg, phi, mean_slope, covariance(), st.floats(0.0, 1.0))
@example(89.9, 0.0, 90.0, np.pi, (0.0, 0.0), np.diag([1e-6, 1e-2]), 0.04)  # light on the horizon
@example(89.9, 0.0, 89.9, 0.0, (3.0, 0.0), np.diag([1e-6, 1e-6]), 1.0)
def test_point_light_finite_and_equal_to_beckmann_brdf(to, po, ti, pi_, mu, cov, f0):
    wo, wi = direction(to, po), direction(ti, pi_)
    v = point_light(wo, wi, mu, cov)
    vf = point_light(wo, wi, mu, cov, f0=f0)
    vn = point_light(wo, wi, mu, cov, shadowing=False, lambda_fit="walter")
    for x in (v, vf, vn):
        assert np.isfinite(x) and x >= 0.0
    assert vf <= v * (1 + 1e-12) + 1e-300  # Schlick's F <= 1
    if wo[2] > 0 and wi[2] > 0:
        # LEADR supplemental 3.3 is the cosine-weighted non-centred Beckmann BRDF
        ref = Beckmann(mu, cov).eval(wo, wi)
        assert v == pytest.approx(ref, rel=1e-6, abs=1e-9 * max(1.0, ref))
    if wi[2] <= 0.0 and np.hypot(*mu) == 0.0:
        assert v == 0.0  # a light at or below the horizon of a centred surface is shadowed


def test_point_light_energy_at_most_one():
    # quadrature over the light hemisphere of the cosine-weighted BRDF (Fresnel 1) <= 1
    x, w = np.polynomial.legendre.leggauss(96)
    th, ph = (x + 1) / 2 * (np.pi / 2), (x + 1) * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    jac = np.sin(T) * (np.pi / 4) * np.pi * np.outer(w, w)
    for t, mu, cov in [(0.0, (0.0, 0.0), np.eye(2) * 0.5),
                       (80.0, (0.3, -0.2), np.diag([0.3, 0.01])),
                       (89.9, (0.0, 0.0), np.eye(2) * 2.0)]:
        e = np.sum(point_light(direction(t, 0.3), d, mu, cov) * jac)
        assert 0.0 <= e <= 1.0 + 1e-3


@settings(max_examples=N // 2)
@given(below_deg, phi, theta_deg, phi, mean_slope, covariance(), st.integers(1, 7))
@example(135.0, 0.0, 90.0, 0.0, (0.0, 0.0), np.diag([1e-6, 1e-2]), 1)  # view below the surface
def test_grid_integrators_bounded(to, po, tl, pl, mu, cov, n):
    wo, wl = direction(to, po), direction(tl, pl)
    d = diffuse_directional(wo, wl, mu, cov, n)
    # E(m) / pi = max(0, m.wl) / pi averaged with positive weights: in [0, 1 / pi]
    assert np.isfinite(d) and 0.0 <= d <= 1.0 / np.pi + 1e-12
    m, wgt, cell = grid_normals(mu, cov, n)
    assert np.allclose(np.linalg.norm(m, axis=-1), 1.0) and wgt.sum() == pytest.approx(1.0)
    assert np.isfinite(cell) and cell > 0.0
    a = artificial_micronormal(wo, np.array(mu))
    assert np.isclose(np.linalg.norm(a), 1.0)


@pytest.fixture(scope="module")
def white_env():
    return EnvMap(np.ones((8, 16, 3)))


@settings(max_examples=N // 2)
@given(below_deg, phi, mean_slope, covariance(), st.sampled_from([1, 3, 5]))
@example(89.9, 0.0, (0.0, 0.0), np.diag([1e-6, 1e-6]), 5)
def test_env_specular_of_white_env_is_one(white_env, t, p, mu, cov, n):
    # a constant environment of radiance 1 reflects exactly 1 (normalised weights, F = 1)
    wo = direction(t, p)
    assert np.allclose(env_specular(white_env, wo, mu, cov, n), 1.0, atol=1e-9)
    sh = np.zeros((9, 3))
    sh[0] = 2.0 * np.sqrt(np.pi)  # L = 1 everywhere: E(m) = pi, diffuse albedo-1 radiance 1
    assert np.allclose(diffuse_sh(sh, wo, mu, cov, n), 1.0, atol=1e-6)


@settings(max_examples=N)
@given(st.integers(0, 2**31), st.floats(0.0, 2.0), st.sampled_from([1, 2, 8]))
def test_moment_maps_give_valid_statistics(seed, base, size):
    h = np.random.default_rng(seed).normal(size=(size, size)) * 3.0
    maps = moments(h, base_roughness=base)
    for level in maps.chain.levels:
        mean, cov = shading_stats(level, base)
        assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
        # positive definite (Sylvester's criterion)
        assert np.all(cov[..., 0, 0] > 0) and np.all(np.linalg.det(cov) > 0)
    s = slopes_from_height(h)
    mean, cov = shading_stats(maps.chain.levels[-1][0, 0], 0.0)
    ref = np.cov(s.reshape(-1, 2).T, bias=True) + 1e-6 * np.eye(2)
    assert np.allclose(mean, s.reshape(-1, 2).mean(0), atol=1e-12)
    assert np.allclose(cov, ref, atol=1e-9)
    assert np.allclose(stats_to_moments(mean, cov - 1e-6 * np.eye(2)), maps.chain.levels[-1][0, 0],
                       atol=1e-9)


@settings(max_examples=N)
@given(st.floats(0.0, 89.9), phi, st.floats(0.1, 10.0))
def test_slopes_from_normals_scale_invariant(t, p, scale):
    n = direction(t, p)
    s = slopes_from_normals(n * scale)
    assert np.allclose(s, -n[:2] / n[2], rtol=1e-9, atol=1e-12)


@settings(max_examples=N)
@given(st.floats(0.0, 1.0), st.floats(-2.0, 2.0))
def test_schlick_in_unit_interval(f0, c):
    f = schlick(f0, c)
    assert f0 - 1e-15 <= f <= 1.0 + 1e-15


def test_gaussian_grid_moments():
    # closed form from the docstring: sum w p^2 + h^2 / 12 = 1, weights sum to 1
    for n in (3, 5, 9):
        p, w, h = gaussian_grid(n)
        assert (w.sum() == pytest.approx(1.0)
                and np.sum(w * p * p) + h * h / 12 == pytest.approx(1.0))


# -- invalid input -------------------------------------------------------------------------------

GOOD_COV = np.diag([0.1, 0.2])


@pytest.mark.parametrize("cov", [np.diag([0.0, 0.1]), np.diag([-0.1, 0.1]),
                                 [[0.1, 0.2], [0.2, 0.1]],
                                 np.full((2, 2), np.nan), np.eye(3), [[0.1, 0.05], [0.0, 0.1]]])
def test_bad_covariances_rejected(cov):
    wo = [0.0, 0.0, 1.0]
    expect_error(lambda: point_light(wo, wo, (0.0, 0.0), cov), "slope_cov")
    expect_error(lambda: diffuse_directional(wo, wo, (0.0, 0.0), cov), "slope_cov")
    expect_error(lambda: grid_normals((0.0, 0.0), cov, 3), "slope_cov")


def test_leadr_rejects_bad_arguments(white_env):
    wo = np.array([0.0, 0.0, 1.0])
    expect_error(lambda: point_light([0.0, 0.0, 2.0], wo, (0, 0), GOOD_COV), "wo")
    expect_error(lambda: point_light(wo, [np.nan, 0, 1], (0, 0), GOOD_COV), "wi")
    expect_error(lambda: point_light(wo, wo, (0, 0, 0), GOOD_COV), "mean_slope")
    expect_error(lambda: point_light(wo, wo, (0, 0), GOOD_COV, f0=np.nan), "f0")
    expect_error(lambda: point_light(wo, wo, (0, 0), GOOD_COV, f0=1.5), "f0")
    expect_error(lambda: point_light(wo, wo, (0, 0), GOOD_COV, lambda_fit="x"), "lambda_fit")
    expect_error(lambda: point_light(np.tile(wo, (3, 1)), np.tile(wo, (4, 1)), (0, 0), GOOD_COV),
                 "wo, wi")
    expect_error(lambda: schlick(0.04, np.nan), "cos_theta")
    expect_error(lambda: schlick(-0.1, 0.5), "f0")
    expect_error(lambda: artificial_micronormal([0, 0, 3.0], (0, 0)), "wo")
    expect_error(lambda: artificial_micronormal(wo, (np.nan, 0)), "mean_slope")
    expect_error(lambda: diffuse_directional(np.tile(wo, (3, 1)), np.tile(wo, (4, 1)), (0, 0),
                                             GOOD_COV), "wo, wl")
    expect_error(lambda: diffuse_directional(np.tile(wo, (4, 1)), wo, np.zeros((3, 2)), GOOD_COV),
                 "mean_slope")
    expect_error(lambda: diffuse_sh(np.zeros((4, 3)), wo, (0, 0), GOOD_COV), "sh_coeffs")
    expect_error(lambda: diffuse_sh(np.full((9, 3), np.nan), wo, (0, 0), GOOD_COV), "sh_coeffs")
    expect_error(lambda: env_specular("env.exr", wo, (0, 0), GOOD_COV), "env")
    expect_error(lambda: env_specular(white_env, wo, (0, 0), GOOD_COV, f0=2.0), "f0")
    expect_error(lambda: env_specular(white_env, wo, (0, 0), GOOD_COV, lod_bias=np.nan),
                 "lod_bias")
    expect_error(lambda: env_specular(white_env, wo, (0, 0), GOOD_COV, to_world=np.eye(2)),
                 "to_world")
    expect_error(lambda: env_specular(white_env, np.tile(wo, (3, 1)), np.zeros((4, 2)),
                                      GOOD_COV), "mean_slope")
    expect_error(lambda: gaussian_grid(0), "n")
    expect_error(lambda: gaussian_grid(3, "wide"), "spacing")
    expect_error(lambda: moments(np.zeros((4, 4)), base_roughness=-1.0), "base_roughness")
    expect_error(lambda: moments(np.zeros((4, 4, 4))), "data")
    expect_error(lambda: moments(np.zeros((4, 4)), texel_size=0.0), "texel_size")
    expect_error(lambda: slopes_from_normals([0.0, 0.6, -0.8]), "normal_map")
    expect_error(lambda: shading_stats(np.zeros(4)), "moments")
    expect_error(lambda: stats_to_moments((0, 0), np.zeros((1, 1))), "cov")


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_integer_normal_maps_are_not_taken_for_normals(dtype):
    # 8/16-bit colours have n_z > 0 everywhere: they used to give garbage slopes silently
    rgb = np.full((4, 4, 3), np.iinfo(dtype).max // 2, dtype)
    rgb[..., 2] = np.iinfo(dtype).max
    expect_error(lambda: slopes_from_normals(rgb), "decode_normals")
    expect_error(lambda: moments(rgb), "decode_normals")


def test_empty_batches(white_env):
    # an empty batch of views gives an empty result
    e3 = np.zeros((0, 3))
    assert env_specular(white_env, e3, (0, 0), GOOD_COV).shape == (0, 3)
    assert diffuse_sh(np.zeros((9, 3)), e3, (0, 0), GOOD_COV).shape == (0, 3)
    assert point_light(e3, e3, (0, 0), GOOD_COV).shape == (0,)


# Inputs that raised TypeError, ValueError, ZeroDivisionError or OverflowError (or were accepted:
# the string "0.5" as a number) instead of a PrefilterError naming the argument.
_ENV = EnvMap(procedural_env(8))
_WO, _H = np.array([0.0, 0.0, 1.0]), np.zeros((4, 4))
BAD_CALLS = [(f"procedural_env({s!r:.10})", lambda s=s: procedural_env(s), "size")
             for s in (None, 0, -1, 1.5, "64", True, [4], np.nan)] + [
    ("procedural_env(10**30)", lambda: procedural_env(10**30), "size"),
    ("procedural_env(10**9)", lambda: procedural_env(10**9), "size"),  # memory
    ("lod_bias array", lambda: env_specular(_ENV, _WO, (0, 0), GOOD_COV, lod_bias=np.ones(2)),
     "lod_bias"),
    ("lod_bias string", lambda: env_specular(_ENV, _WO, (0, 0), GOOD_COV, lod_bias="0.5"),
     "lod_bias"),
    ("lod_bias 1e300", lambda: env_specular(_ENV, _WO, (0, 0), GOOD_COV, lod_bias=1e300),
     "lod_bias"),
    ("cov 1e300", lambda: grid_normals((0, 0), np.full((2, 2), 1e300), 3), "slope_cov"),
    ("cov overflowing det", lambda: point_light(_WO, _WO, (0, 0), np.diag([1e200, 1e200])),
     "slope_cov"),
    ("mean slope 1e300", lambda: env_specular(_ENV, _WO, (1e300, 0), GOOD_COV), "mean_slope"),
    ("moments ragged", lambda: moments([[0.1, 0.2], [0.3]]), "data"),
    ("moments texel_size string", lambda: moments(_H, texel_size="0.5"), "texel_size"),
    ("moments base_roughness string", lambda: moments(_H, base_roughness="0.5"),
     "base_roughness"),
    ("moments 6x6", lambda: moments(np.zeros((6, 6))), "data"),
    ("moments slopes 1e200", lambda: moments(np.full((4, 4, 2), 1e200)), "data"),
    ("slopes_from_height string", lambda: slopes_from_height(_H, "0.5"), "texel_size"),
    ("gaussian_grid string", lambda: gaussian_grid(3, "0.5"), "spacing"),
    ("gaussian_grid 1e300", lambda: gaussian_grid(3, 1e300), "spacing"),
    ("shading_stats string", lambda: shading_stats(np.zeros(5), "0.5"), "base_roughness"),
    ("shading_stats array", lambda: shading_stats(np.zeros(5), np.ones(2)), "base_roughness"),
]


@pytest.mark.parametrize("what,fn,name", BAD_CALLS, ids=[c[0] for c in BAD_CALLS])
def test_public_api_raises_prefilter_errors_naming_the_argument(what, fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert str(err.value).startswith(name + ":"), str(err.value)
