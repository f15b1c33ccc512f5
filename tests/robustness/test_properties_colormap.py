"""Property-based tests of prefilter.colormap: tables, texture / noise / height / slope filtering
and the combinations, at the edges (means far outside the table, grazing views, lights on and
below the horizon, footprints smaller than a texel and larger than the texture)."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import integrate

from prefilter.colormap import (
    NoiseStd,
    as_colormap,
    combine_linear,
    combine_product,
    filter_height,
    filter_noise,
    filter_slope,
    filter_texture,
    fit_height_params,
    gaussian_operator,
    height_distribution,
    height_moments_approx,
    height_moments_exact,
    lookup,
    mean_visibility,
    moments_mip,
    naive_texture,
    prefilter_table,
    slope_distribution,
    slope_prefilter_table,
    smith_lambda,
    smith_lambda_direction,
    texture_stats,
)
from prefilter.errors import PrefilterError
from prefilter.texture import MipChain

N = settings.default.max_examples

RNG = np.random.default_rng(11)
CMAP = RNG.random((24, 3))
TABLES = {e: prefilter_table(CMAP, (-1.0, 2.0), 0.5, 32, edge=e)
          for e in ("clamp", "mirror", "periodic")}
SLOPE_TABLE = slope_prefilter_table(RNG.random((16, 16, 3)), 1.0, 0.5, 8)
LO, HI = CMAP.min(0), CMAP.max(0)

big = st.one_of(st.sampled_from([0.0, 1e18, -1e18, 1e300, -1e300]), st.floats(-10.0, 10.0))
theta_deg = st.one_of(st.sampled_from([0.0, 1e-5, 89.9]), st.floats(0.0, 89.9))
light_deg = st.one_of(st.sampled_from([90.0, 120.0, 180.0]), st.floats(0.0, 180.0))
phi = st.floats(0.0, 2 * np.pi)


def direction(t_deg, p):
    t = np.radians(t_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


@st.composite
def covariance(draw, lo=-3.0):
    sx = 10.0 ** draw(st.floats(lo, 0.5))
    sy = 10.0 ** draw(st.floats(lo, 0.5))
    rho = draw(st.floats(-0.99, 0.99))
    return np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


def in_hull(c, lo=LO, hi=HI, tol=1e-9):
    return np.all(np.isfinite(c)) and np.all(c >= lo - tol) and np.all(c <= hi + tol)


# -- the pre-convolved table ---------------------------------------------------------------------


@settings(max_examples=N)
@given(big, st.one_of(st.sampled_from([0.0, 1e300]), st.floats(0.0, 10.0)),
       st.sampled_from(["clamp", "mirror", "periodic"]))
@example(1e300, 0.0, "clamp")  # the int64 cast wrapped: the left colour for a huge mean
@example(1e18, 0.0, "clamp")
def test_table_lookup_is_a_convex_combination(mean, sigma, edge):
    t = TABLES[edge]
    c = t.lookup(mean, sigma)
    # Gaussian blur and linear interpolation weight colours positively, summing to 1
    assert in_hull(c)
    if edge == "clamp" and abs(mean) >= 1e18:
        assert np.allclose(c, CMAP[-1] if mean > 0 else CMAP[0], atol=1e-9) or sigma > 0


@settings(max_examples=N)
@given(st.integers(2, 40), st.floats(0.0, 3.0), st.sampled_from(["clamp", "mirror", "periodic"]),
       st.integers(1, 40))
def test_gaussian_operator_rows_are_weights(n, sigma, edge, n_out):
    op = gaussian_operator(n, sigma, edge, n_out)
    assert op.shape == (n_out, n) and np.all(op >= -1e-15)
    assert np.allclose(op.sum(1), 1.0, atol=1e-12)


def test_constant_colour_map_is_invariant():
    t = prefilter_table(np.full((8, 2), 0.3), (0.0, 1.0), 2.0, 16)
    assert np.allclose(t.lookup(np.linspace(-5, 5, 11), np.linspace(0, 5, 11)), 0.3)
    assert np.allclose(as_colormap(lambda v: np.stack([v, 1 - v], -1), (0, 1), 4)[:, 0],
                       [0.125, 0.375, 0.625, 0.875])


# -- height filtering ----------------------------------------------------------------------------


@settings(max_examples=N)
@given(st.one_of(st.sampled_from([1e-12, np.inf, 1e300]), st.floats(1e-3, 1e3)),
       st.floats(1e-3, 10.0))
@example(1e-12, 10.0)
def test_smith_lambda_matches_its_integral(cot, sigma):
    lam = smith_lambda(cot, sigma)
    assert np.isfinite(lam) and lam >= 0.0
    if 1e-2 < cot / sigma < 30:
        # Smith 1967 / Heitz et al. 2013 eq. 3: Lambda = E[max(0, q - cot)] / cot, q ~ N(0, s^2)
        f = lambda q: (q - cot) * np.exp(-0.5 * (q / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)
        ref = integrate.quad(f, cot, cot + 40 * sigma, epsabs=1e-14)[0] / cot
        assert lam == pytest.approx(ref, rel=1e-6, abs=1e-14)


@settings(max_examples=N)
@given(theta_deg, phi, light_deg, phi, covariance(), st.floats(1e-3, 10.0))
@example(89.9, 0.0, 90.0, 1.0, np.diag([1e-6, 1e-2]), 1.0)  # a light exactly on the horizon
@example(89.9, 0.0, 180.0, 1.0, np.diag([1e-6, 1e-2]), 1.0)  # and straight below it
def test_height_distribution_finite_for_any_light(to, po, ti, pi_, cov, sigma_h):
    wo, wi = direction(to, po), direction(ti, pi_)
    mu, sd, v = height_distribution(wo, wi, cov, sigma_h)
    assert np.isfinite(mu) and np.isfinite(sd) and sd > 0.0 and 0.0 <= v <= 1.0
    if wi[2] <= 0.0:
        assert v == 0.0  # unlit
    c = filter_height(TABLES["clamp"], wo, wi, cov, sigma_h, noise_sigma=0.1)
    assert in_hull(c, np.minimum(LO, 0.0), HI)  # V_bar <= 1 scales the colour down


@settings(max_examples=N)
@given(st.one_of(st.sampled_from([0.0, 1e3, 1e6]), st.floats(0.0, 100.0)), st.floats(1e-3, 1e3))
def test_height_moments_finite(lam, sigma_h):
    mu, sd = height_moments_exact(lam, sigma_h)
    mua, sda = height_moments_approx(lam, sigma_h)
    for v in (mu, sd, mua, sda):
        assert np.isfinite(v)
    # L >= 0 tilts D_h towards the top: mean height >= 0, narrower than the heights
    assert mu >= -1e-9 * sigma_h and 0.0 <= sd <= sigma_h * (1 + 1e-9)
    assert 0.0 < mean_visibility(lam, lam) <= 1.0


# -- slope filtering -----------------------------------------------------------------------------


@settings(max_examples=N)
@given(theta_deg, phi, st.tuples(st.floats(-3, 3), st.floats(-3, 3)), covariance(lo=-4.0))
@example(89.9, 0.0, (3.0, 0.0), np.diag([1e-8, 1e-8]))  # mean slope almost behind the view
@example(89.9, 0.0, (0.0, 0.0), np.diag([1e-8, 10.0]))  # 1:3000 anisotropy
@example(1e-5, 0.0, (0.0, 0.0), np.diag([1e-6, 1e-6]))  # head-on mirror: variance was removed
def test_slope_distribution_is_a_gaussian(t, p, mu, cov):
    wo = direction(t, p)
    m, c = slope_distribution(wo, mu, cov)
    sd_t = np.sqrt(wo[:2] @ cov @ wo[:2])
    alpha = (wo[2] - wo[:2] @ np.array(mu)) / sd_t if sd_t > 0 else np.inf
    if alpha > 1e3:
        # the ramp max(0, t) is ~constant over the slopes: D_s is the slope Gaussian up to the
        # variance 1 - 1/alpha^2 along the ramp (closed form; it used to cancel catastrophically)
        assert np.allclose(c, cov, rtol=0.0, atol=(2 / alpha**2 + 1e-12) * np.abs(cov).max())
    assert np.all(np.isfinite(m)) and np.all(np.isfinite(c))
    assert np.allclose(c, c.T) and np.linalg.eigvalsh(c).min() >= -1e-12 * np.abs(c).max()
    # the view ramp only removes variance (the truncated ramp has variance <= the Gaussian's)
    assert np.trace(c) <= np.trace(cov) * (1 + 1e-9) + 1e-300
    col = filter_slope(SLOPE_TABLE, wo, mu, cov)
    lo, hi = SLOPE_TABLE.stack[0].min((0, 1)), SLOPE_TABLE.stack[0].max((0, 1))
    assert in_hull(col, lo, hi)


@settings(max_examples=N)
@given(big, big)
@example(1e300, -1e300)  # wrapped to the wrong edge before the int64 cast was saturated
def test_slope_table_far_outside(sx, sy):
    c = SLOPE_TABLE.naive(np.array([sx, sy]))
    n = SLOPE_TABLE.n
    i = 0 if sy < -1 else (n - 1 if sy > 1 else None)
    j = 0 if sx < -1 else (n - 1 if sx > 1 else None)
    if i is not None and j is not None:
        assert np.allclose(c, SLOPE_TABLE.stack[0, i, j])  # clamped to the corner
    assert np.all(np.isfinite(c))


# -- textures and noise --------------------------------------------------------------------------

footprint = st.one_of(st.sampled_from([0.0, 1e-4, 50.0]), st.floats(-2.0, 2.0))


@settings(max_examples=N)
@given(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), footprint, footprint, footprint, footprint,
       st.booleans())
@example(0.5, 0.5, 0.0, 0.0, 0.0, 0.0, False)  # smaller than a texel
@example(0.5, 0.5, 50.0, 0.0, 0.0, 50.0, True)  # larger than the texture
def test_texture_stats_bounded(u, v, a, b, c, d, aniso):
    f = RNG.normal(size=(16, 16))
    chain = moments_mip(f)
    dudv = np.array([[a, b], [c, d]])
    mean, sigma = texture_stats(chain, [u, v], dudv, anisotropic=aniso)
    assert f.min() - 1e-9 <= mean <= f.max() + 1e-9
    assert 0.0 <= sigma <= (f.max() - f.min()) / 2 + 1e-9  # Popoviciu's bound on a std
    assert in_hull(filter_texture(TABLES["mirror"], chain, [u, v], dudv, anisotropic=aniso))
    assert in_hull(naive_texture(TABLES["clamp"], chain, [u, v], dudv))


@settings(max_examples=N // 2)
@given(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), footprint, footprint, st.booleans())
def test_filter_noise_bounded(u, v, a, d, aniso):
    noise_chain = MipChain(RNG.normal(size=(16, 16)))
    std = NoiseStd.from_procedural(16, 2.0, 1.0)
    filt, naive = filter_noise(TABLES["periodic"], noise_chain, std, [u, v],
                               np.diag([a, d]), anisotropic=aniso)
    assert in_hull(filt) and in_hull(naive)


@settings(max_examples=N)
@given(st.floats(0, 1), st.floats(0, 1), st.floats(0, 1), st.floats(0, 1))
def test_combinations_finite(k0, k1, k2, v):
    c = RNG.random((3, 4, 3))
    out = combine_linear((k0, k1, k2), c[0], c[1], c[2], np.full(4, v), l_bar=2.0)
    assert out.shape == (4, 3) and np.all(np.isfinite(out))
    assert np.allclose(combine_product(c[0], c[1], c[2]), c[0] * c[1] * c[2])


# -- invalid input -------------------------------------------------------------------------------


def test_tables_reject_bad_input():
    t = TABLES["clamp"]
    expect_error(lambda: t.lookup(np.nan, 0.1), "mean")
    expect_error(lambda: t.lookup(0.5, -0.1), "sigma")
    expect_error(lambda: t.lookup(np.zeros(3), np.zeros(4)), "mean, sigma")
    expect_error(lambda: lookup("table.png", 0.5, 0.1), "table")
    expect_error(lambda: prefilter_table(CMAP, (1.0, 0.0)), "value_range")
    expect_error(lambda: prefilter_table(CMAP, sigma_max=0.0), "sigma_max")
    expect_error(lambda: prefilter_table(CMAP, edge="wrap"), "edge")
    expect_error(lambda: prefilter_table(np.full((4, 3), np.nan)), "colormap")
    expect_error(lambda: prefilter_table(CMAP[:1]), "colormap")
    expect_error(lambda: as_colormap(lambda v: v[:3], (0, 1), 8), "colormap(v)")
    expect_error(lambda: gaussian_operator(8, -1.0), "sigma")
    expect_error(lambda: gaussian_operator(1, 0.1), "n")


def test_height_and_slope_reject_bad_input():
    up, cov = np.array([0.0, 0.0, 1.0]), np.eye(2) * 0.1
    expect_error(lambda: smith_lambda(0.0, 0.1), "cot_theta")
    expect_error(lambda: smith_lambda("steep", 0.1), "cot_theta")
    expect_error(lambda: smith_lambda(1.0, 0.0), "sigma_s")
    expect_error(lambda: smith_lambda_direction([0.0, 0.6, -0.8], cov), "w")
    expect_error(lambda: height_distribution([0.0, 0.6, -0.8], up, cov), "wo")
    expect_error(lambda: height_distribution(up, [0.0, 0.0, 3.0], cov), "wi")
    expect_error(lambda: height_distribution(up, up, np.diag([0.1, -0.1])), "slope_cov")
    expect_error(lambda: height_distribution(up, up, cov, sigma_h=0.0), "sigma_h")
    expect_error(lambda: height_moments_approx(1.0, -1.0), "sigma_h")
    expect_error(lambda: height_moments_approx(1.0, 1.0, (1.0, np.nan, 1.0, 1.0)), "params")
    expect_error(lambda: height_moments_exact(-1.0), "lam")
    expect_error(lambda: mean_visibility(np.nan, 0.0), "lambda_o")
    expect_error(lambda: filter_height(None, up, up, cov), "table")
    expect_error(lambda: filter_height(TABLES["clamp"], up, up, cov, noise_sigma=-1.0),
                 "noise_sigma")
    expect_error(lambda: slope_distribution([0.0, 0.6, -0.8], (0, 0), cov), "wo")
    expect_error(lambda: slope_distribution(up, (0, 0), [[0.1, 0.2], [0.0, 0.1]]), "cov")
    expect_error(lambda: slope_distribution(up, (0, 0), -cov), "cov")
    expect_error(lambda: slope_distribution(up, np.zeros((3, 2)), np.stack([cov] * 4)), "mean")
    expect_error(lambda: filter_slope(TABLES["clamp"], up, (0, 0), cov), "table")
    expect_error(lambda: SLOPE_TABLE.lookup((0, 0), cov, 0), "n_taps")
    expect_error(lambda: slope_prefilter_table(np.zeros((4, 5, 3))), "colormap")
    expect_error(lambda: slope_prefilter_table(np.zeros((4, 4, 3)), extent=0.0), "extent")


def test_textures_and_combinations_reject_bad_input():
    chain = moments_mip(np.zeros((4, 4)))
    expect_error(lambda: texture_stats(MipChain(np.zeros((4, 4))), [0, 0], np.eye(2)), "chain")
    expect_error(lambda: texture_stats(chain, [np.nan, 0], np.eye(2)), "uv")
    expect_error(lambda: texture_stats(chain, [0, 0], np.eye(3)), "dudv")
    expect_error(lambda: filter_texture("t", chain, [0, 0], np.eye(2)), "table")
    expect_error(lambda: NoiseStd([1.0, -0.5]), "level_variance")
    expect_error(lambda: NoiseStd([1.0, 0.5], sigma=np.nan), "sigma")
    noise_chain = MipChain(np.zeros((4, 4)))
    expect_error(lambda: filter_noise(TABLES["clamp"], chain, NoiseStd([1.0]), [0, 0], np.eye(2)),
                 "noise_chain")
    expect_error(lambda: filter_noise(TABLES["clamp"], noise_chain, [1.0], [0, 0], np.eye(2)),
                 "noise_std")
    c = np.zeros((4, 3))
    expect_error(lambda: combine_linear((1, 1), c, c, c, 1.0), "kappa")
    expect_error(lambda: combine_linear((1, 1, 1), c, c, c, np.nan), "v_bar")
    expect_error(lambda: combine_linear((1, 1, 1), c, np.zeros((5, 3)), c, 1.0), "c0, ch, cs")
    expect_error(lambda: combine_product(c, c, c, l_bar=np.inf), "l_bar")


def test_height_fit_checks_its_grid_and_beats_the_paper():
    # the refit is a least-squares optimum over the same grid: never worse than the paper's
    params, report = fit_height_params(50.0, 60)
    assert np.all(np.isfinite(params))
    assert report["fit"]["mu_rms"] <= report["paper"]["mu_rms"] + 1e-12
    assert report["fit"]["sigma_rms"] <= report["paper"]["sigma_rms"] + 1e-12
    # were numpy / scipy errors (zero-size reduction, float n) or a NaN grid
    expect_error(lambda: fit_height_params(-1.0), "lam_max")
    expect_error(lambda: fit_height_params(10.0, 0), "n")
    expect_error(lambda: fit_height_params(10.0, 2.5), "n")


# Inputs that raised TypeError / ValueError / OverflowError (or were accepted: the string "0.5")
# instead of a PrefilterError naming the argument.
BAD_CALLS = [
    ("sigma None", lambda: gaussian_operator(8, None), "sigma"),
    ("sigma dict", lambda: gaussian_operator(8, {"a": 1}), "sigma"),
    ("sigma complex", lambda: gaussian_operator(8, 1 + 2j), "sigma"),
    ("sigma string", lambda: gaussian_operator(8, "0.5"), "sigma"),
    ("sigma list", lambda: gaussian_operator(8, [0.1, 0.2]), "sigma"),
    ("sigma 10**400", lambda: gaussian_operator(8, 10**400), "sigma"),
    ("sigma_max array", lambda: prefilter_table(CMAP, sigma_max=np.array([0.1, 0.2])),
     "sigma_max"),
    ("sigma_max string", lambda: prefilter_table(CMAP, sigma_max="0.25"), "sigma_max"),
    ("slope sigma_max array",
     lambda: slope_prefilter_table(np.zeros((4, 4, 3)), sigma_max=np.array([0.1, 0.2])),
     "sigma_max"),
    ("slope extent string", lambda: slope_prefilter_table(np.zeros((4, 4, 3)), extent="1"),
     "extent"),
    ("n_taps 10**30", lambda: filter_slope(SLOPE_TABLE, [0, 0, 1.0], (0, 0), np.eye(2) * 0.1,
                                           n_taps=10**30), "n_taps"),
    ("moments_mip 6x6", lambda: moments_mip(np.zeros((6, 6))), "data"),
    ("moments_mip 1e200", lambda: moments_mip(np.full((4, 4), 1e200)), "data"),
    ("moments_mip ragged", lambda: moments_mip([[0.1, 0.2], [0.3]]), "data"),
    ("lam_max array", lambda: fit_height_params(np.array([10.0, 20.0]), 8), "lam_max"),
    ("fit n 10**12", lambda: fit_height_params(10.0, 10**12), "n"),
    ("NoiseStd sigma string", lambda: NoiseStd([1.0, 0.5], sigma="0.5"), "sigma"),
]


@pytest.mark.parametrize("what,fn,name", BAD_CALLS, ids=[c[0] for c in BAD_CALLS])
def test_public_api_raises_prefilter_errors_naming_the_argument(what, fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert str(err.value).startswith(name + ":"), str(err.value)
