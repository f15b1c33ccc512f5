"""Property-based tests of prefilter.texture: normal-map encodings (8/16-bit, OpenGL/DirectX),
mip chains and footprints (smaller than a texel, larger than the texture), procedural data."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.texture import (
    MipChain,
    decode_normals,
    encode_normals,
    footprint_axes,
    height_map,
    lod_from_footprint,
    moment_chain,
    moments_to_stats,
    noise,
    noise_level_variance,
    normal_map,
    slopes_to_normals,
)

N = settings.default.max_examples


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


theta_deg = st.one_of(st.sampled_from([0.0, 89.9]), st.floats(0.0, 89.9))
phi = st.floats(0.0, 2 * np.pi)


def direction(t_deg, p):
    t = np.radians(t_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


# -- normal maps ---------------------------------------------------------------------------------


@settings(max_examples=N)
@given(theta_deg, phi, st.sampled_from(["opengl", "directx"]))
@example(89.9, 0.0, "opengl")
def test_normal_encoding_round_trip_and_green_convention(t, p, conv):
    n = direction(t, p)
    c = encode_normals(n, conv)
    assert np.all((c >= 0.0) & (c <= 1.0))
    assert np.allclose(decode_normals(c, conv), n, atol=1e-12)
    # reading with the other convention mirrors y (closed form: only the green sign differs)
    other = "directx" if conv == "opengl" else "opengl"
    assert np.allclose(decode_normals(c, other), n * [1, -1, 1], atol=1e-12)


@settings(max_examples=N)
@given(theta_deg, phi, st.sampled_from([(np.uint8, 255), (np.uint16, 65535)]))
@example(0.0, 0.0, (np.uint8, 255))
def test_integer_normal_maps_decode_like_their_float_colours(t, p, kind):
    dtype, top = kind
    n = direction(t, p)
    q = np.round(encode_normals(n) * top).astype(dtype)
    d = decode_normals(q)
    assert np.allclose(d, decode_normals(q / top), atol=1e-15)
    # quantisation error of (n + 1) / 2 to 1/top per channel; z clamped at the horizon
    assert np.linalg.norm(d - n) < 4.0 / top + 1e-3 * (t > 89.0)


@pytest.mark.parametrize("rgb,hint", [
    (np.full((2, 2, 3), 200.0), "255"),  # 8-bit values as floats
    (np.array([0.0, 0.0, 1.0]) * 2 - 1, "[-1, 1]"),  # already decoded
    (np.full((4, 3), np.nan), "finite"),
])
def test_decode_rejects_wrong_ranges_with_a_hint(rgb, hint):
    with pytest.raises(PrefilterError) as err:
        decode_normals(rgb)
    assert "normal map" in str(err.value) and hint in str(err.value)


@pytest.mark.parametrize("rgb", [np.zeros((2, 2, 3), np.int32), np.ones((2, 3), bool),
                                 np.array([[0.5, 0.5, 0.2]]), np.array([0.5, 0.5, 0.5]),
                                 np.array([0.5, 0.5]), np.array(0.5)])
def test_decode_rejects_non_normal_maps(rgb):
    expect_error(lambda: decode_normals(rgb), "normal map")


def test_normal_conventions_and_encoding_checked():
    expect_error(lambda: decode_normals([0.5, 0.5, 1.0], "vulkan"), "convention")
    expect_error(lambda: decode_normals([0.5, 0.5, 1.0], None), "convention")
    expect_error(lambda: encode_normals([0.0, 0.0, 2.0]), "normals")  # not unit
    expect_error(lambda: encode_normals([0.0, 0.6, -0.8]), "normals")  # below the surface
    expect_error(lambda: encode_normals([[0.0, 1.0]]), "normals")


@settings(max_examples=N)
@given(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3))
def test_slopes_to_normals(sx, sy):
    n = slopes_to_normals([sx, sy])
    assert np.isclose(np.linalg.norm(n), 1.0) and n[2] > 0.0
    assert np.allclose(-n[:2] / n[2], [sx, sy], rtol=1e-9, atol=1e-12)


# -- mip chains and footprints --------------------------------------------------------------------


@st.composite
def images(draw):
    h = 2 ** draw(st.integers(0, 4))
    w = 2 ** draw(st.integers(0, 4))
    c = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**16))
    return np.random.default_rng(seed).normal(size=(h, w, c))


footprint = st.one_of(st.sampled_from([0.0, 1e-6, 1e3]), st.floats(-50.0, 50.0))


@settings(max_examples=N)
@given(images(), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), footprint, footprint, footprint,
       footprint, st.booleans())
@example(np.ones((4, 4, 1)), 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, True)  # zero footprint
@example(np.ones((4, 4, 1)), 0.5, 0.5, 1e3, 0.0, 0.0, 1e-6, True)  # needle, far beyond 1:8
def test_mip_lookups_stay_in_the_convex_hull(img, u, v, a, b, c, d, aniso):
    chain = MipChain(img)
    uv = np.array([u, v])
    dudv = np.array([[a, b], [c, d]]) / 16.0
    lo, hi = img.min(axis=(0, 1)), img.max(axis=(0, 1))
    # a box-filtered, bilinearly interpolated value is a convex combination of texels
    for val in (chain.lookup(uv, 0.0), chain.lookup(uv, 100.0),
                chain.lookup_footprint(uv, dudv, anisotropic=aniso)):
        assert np.all(np.isfinite(val))
        assert np.all(val >= lo - 1e-9) and np.all(val <= hi + 1e-9)
    # a footprint larger than the texture gives the texture mean (closed form)
    big = chain.lookup_footprint(uv, np.eye(2) * 4.0, anisotropic=aniso)
    assert np.allclose(big, img.mean(axis=(0, 1)), atol=1e-12)


@settings(max_examples=N)
@given(footprint, footprint, footprint, footprint, st.integers(1, 16))
def test_footprint_axes_are_singular_values(a, b, c, d, k):
    J = np.array([[a, b], [c, d]])
    major, minor, direction_ = footprint_axes(J, (8, 4))
    s = np.linalg.svd(J * np.array([4.0, 8.0])[:, None], compute_uv=False)
    assert major == pytest.approx(s[0], rel=1e-7, abs=1e-9)
    assert minor == pytest.approx(s[1], rel=1e-6, abs=1e-6 * (1 + s[0]))
    assert np.isclose(np.linalg.norm(direction_), 1.0)
    for aniso in (False, True):
        lod = lod_from_footprint(J, (8, 4), anisotropic=aniso, max_aniso=k)
        assert np.isfinite(lod) and lod >= 0.0


@settings(max_examples=N)
@given(images())
def test_moment_chain_variances_nonnegative(img):
    chain = moment_chain(img[..., 0])
    for level in chain.levels:
        mean, var = moments_to_stats(level)
        assert np.all(np.isfinite(mean)) and np.all(var >= 0.0)
    mean, var = moments_to_stats(chain.levels[-1])
    assert mean[0, 0] == pytest.approx(img[..., 0].mean()) and var[0, 0] == pytest.approx(
        img[..., 0].var(), abs=1e-12)


def test_mip_and_footprint_reject_bad_input():
    expect_error(lambda: MipChain(np.zeros((3, 4))), "image")
    expect_error(lambda: MipChain(np.zeros(4)), "image")
    expect_error(lambda: MipChain(np.full((4, 4), np.nan)), "image")
    chain = MipChain(np.zeros((4, 4)))
    expect_error(lambda: chain.lookup([np.nan, 0.0]), "uv")
    expect_error(lambda: chain.lookup([0.5, 0.5], np.inf), "lod")
    expect_error(lambda: chain.lookup([0.5]), "uv")
    expect_error(lambda: chain.lookup_footprint([0.5, 0.5], np.eye(3)), "dudv")
    expect_error(lambda: chain.lookup_footprint([0.5, 0.5], np.eye(2), anisotropic=True,
                                                max_aniso=0), "max_aniso")
    expect_error(lambda: footprint_axes(np.full((2, 2), np.nan), (4, 4)), "dudv")
    expect_error(lambda: moment_chain(np.zeros((4, 4, 3))), "data")
    expect_error(lambda: moments_to_stats(np.zeros(3)), "moments")


# -- procedural data -----------------------------------------------------------------------------


@settings(max_examples=N // 3)
@given(st.sampled_from(["gaussian", "anisotropic", "brushed", "scratches", "flakes"]),
       st.sampled_from([8, 16, 32]), st.integers(0, 2**31))
def test_procedural_normal_maps_are_unit_and_upward(kind, size, seed):
    n = normal_map(kind, size, seed)
    assert n.shape == (size, size, 3)
    assert np.allclose(np.linalg.norm(n, axis=-1), 1.0) and np.all(n[..., 2] > 0.0)
    assert np.array_equal(n, normal_map(kind, size, seed))  # same seed, same bytes


@settings(max_examples=N // 3)
@given(st.sampled_from([4, 8, 16]), st.floats(0.25, 64.0, exclude_min=True), st.floats(0.0, 10.0))
def test_noise_level_variances(size, corr, sigma):
    v = noise_level_variance(size, corr, sigma)
    assert np.all(np.isfinite(v)) and v[0] == pytest.approx(sigma**2)
    assert np.all(np.diff(v) <= 1e-12 * (1 + sigma**2))  # averaging never adds variance
    x = noise(size, 0, corr, sigma)
    assert np.all(np.isfinite(x)) and x.shape == (size, size)


def test_procedural_rejects_bad_parameters():
    expect_error(lambda: normal_map("marble"), "kind")
    expect_error(lambda: normal_map("gaussian", 2), "size")
    expect_error(lambda: normal_map("gaussian", 8, None), "seed")
    expect_error(lambda: normal_map("gaussian", 8, 0, rms_slope=-1.0), "rms_slope")
    expect_error(lambda: normal_map("gaussian", 8, 0, rms_slope=np.nan), "rms_slope")
    expect_error(lambda: normal_map("gaussian", 8, 0, bogus=1.0), "bogus")
    expect_error(lambda: height_map("anisotropic", 8, 0, cov=[[1, 2], [2, 1]]), "cov")
    expect_error(lambda: noise(8, 0, corr_length=0.0), "corr_length")
    expect_error(lambda: noise(8, 0, sigma=np.inf), "sigma")
    expect_error(lambda: noise_level_variance(12), "size")
    expect_error(lambda: slopes_to_normals([np.nan, 0.0]), "slopes")


@pytest.mark.parametrize("fn,name", [
    (lambda: normal_map("gaussian", 8, -1), "seed"),                     # was NumPy's ValueError
    (lambda: normal_map("gaussian", 8, 0, rms_slope="0.3"), "rms_slope"),  # was accepted
    (lambda: normal_map("gaussian", 8, 0, corr_length=1e9), "corr_length"),  # NaN slopes
    (lambda: height_map("brushed", 8, 0, length=1e300, width=1e300), "length"),
    (lambda: height_map("anisotropic", 8, 0, cov=[[1e300, 0], [0, 1]]), "cov"),
    (lambda: normal_map("scratches", 8, 0, width=1e9), "width"),         # a 4e9^2 box
    (lambda: normal_map("scratches", 8, 0, count=10**9), "count"),
    (lambda: noise(8, 0, corr_length=1e200), "corr_length"),             # LinAlgError
    (lambda: noise(8, 0, sigma=True), "sigma"),
    (lambda: noise(8, -2), "seed"),
], ids=["seed-1", "rms-string", "corr-1e9", "brushed-1e300", "cov-1e300", "scratch-width",
        "scratch-count", "noise-corr", "noise-bool", "noise-seed"])
def test_procedural_parameters_have_a_domain(fn, name):
    expect_error(fn, name)
