"""Property-based tests of prefilter.glints (P-NDF and constant-time queries): footprints smaller
than a texel and larger than the texture, centres far outside the tile, s outside the disk."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.glints import block_means, elements, hemisphere_ndf, pndf_image, point, range_mean
from prefilter.glints.bake import bake
from prefilter.glints.pndf import pndf
from prefilter.glints.store import load

N = settings.default.max_examples


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


def wavy(size=16, a=0.2):
    # an analytic periodic normal map: s = (a sin(2 pi x / size), a cos(2 pi y / size))
    x = np.arange(size) + 0.5
    X, Y = np.meshgrid(x, x)
    sx, sy = a * np.sin(2 * np.pi * X / size), a * np.cos(2 * np.pi * Y / size)
    return np.stack([sx, sy, np.sqrt(1 - sx * sx - sy * sy)], -1)


NM = wavy()
ELEM = elements(NM)

centre = st.one_of(st.sampled_from([0.0, -1e6, 1e6]), st.floats(-100.0, 100.0))
sigma_p = st.one_of(st.sampled_from([0.0, 1e-3, 0.5, 64.0, 1e4, 1e6]), st.floats(0.0, 40.0))
roughness = st.one_of(st.sampled_from([1e-4, 0.5]), st.floats(1e-3, 0.1))


@settings(max_examples=N)
@given(centre, centre, sigma_p, st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), roughness)
@example(1e6, -1e6, 0.0, 0.0, 0.2, 1e-4)  # a point footprint far outside the tile
def test_pndf_finite_nonnegative(cx, cy, sp, sx, sy, sr):
    d = pndf(NM, [cx, cy], sp, [sx, sy], sr, elements_=ELEM)
    assert np.isfinite(d) and d >= 0.0
    m = np.array([sx, sy, np.sqrt(max(0.0, 1 - sx * sx - sy * sy))])
    assert np.isfinite(hemisphere_ndf(d, m))


def wide_limit(s, sr):
    # sigma_p -> inf: every texel once, N(s; n_i, sr^2 I + sigma_h^2 J_i J_i^T) averaged (the
    # Gaussian footprint integral of each element, Yan et al. 2016), computed here directly
    from prefilter.glints.pndf import SIGMA_H

    n, J = ELEM
    n, J = n.reshape(-1, 2), J.reshape(-1, 2, 2)
    cov = sr * sr * np.eye(2) + SIGMA_H**2 * J @ np.swapaxes(J, -1, -2)
    d = s - n
    q = np.einsum("ki,kij,kj->k", d, np.linalg.inv(cov), d)
    return np.mean(np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(np.linalg.det(cov))))


@settings(max_examples=N)
@given(centre, centre, st.sampled_from([64.0, 1e4, 1e6]), st.floats(-0.3, 0.3),
       st.floats(-0.3, 0.3))
@example(0.0, 0.0, 1e6, 0.0, 0.19)  # hung: 6e13 texel copies under the footprint
def test_pndf_of_footprints_larger_than_the_map(cx, cy, sp, sx, sy):
    d = pndf(NM, [cx, cy], sp, [sx, sy], 0.02, elements_=ELEM)
    assert d == pytest.approx(wide_limit(np.array([sx, sy]), 0.02), rel=1e-9, abs=1e-12)


@settings(max_examples=N // 3)
@given(centre, centre, sigma_p)
@example(0.0, 0.0, 0.0)
@example(0.0, 0.0, 1e6)
@example(3.0, 5.0, 64.0)  # a footprint four times the tile
def test_pndf_image_is_a_density(cx, cy, sp):
    # sigma_r = 0.02 keeps each element's Gaussian inside the support [-0.5, 0.5]^2 (normals
    # within 0.2 of the pole): the image must hold the whole unit mass (closed form), up to
    # the 4-sigma truncation (< 1.3e-4 per axis)
    img = pndf_image(NM, [cx, cy], sp, 32, 0.5, 0.02, elements_=ELEM)
    assert np.all(np.isfinite(img)) and np.all(img >= 0.0)
    assert img.sum() * (1.0 / 32) ** 2 == pytest.approx(1.0, abs=2e-3)


@pytest.fixture(scope="module")
def glints_map(tmp_path_factory):
    out = tmp_path_factory.mktemp("glints") / "wavy.npz"
    bake(NM, out, rank=4, ndf_res=16, block=8, support=0.5, cell=16, converge=0.0,
         progress=False)
    return load(out)


@settings(max_examples=N)
@given(centre, centre, sigma_p, st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(1e-3, 1.0))
@example(1e6, -1e6, 0.0, 0.0, 0.2, 1e-3)
@example(0.0, 0.0, 1e6, 0.6, 0.6, 0.5)  # footprint far larger than the map, s off the support
def test_queries_finite(glints_map, cx, cy, sp, sx, sy, w):
    p = point(glints_map, [cx, cy], sp, [sx, sy])
    r = range_mean(glints_map, [cx, cy], sp, [sx, sy], [sx + w, sy + w])
    # compressed images may ring slightly below zero (CP); never NaN
    assert np.isfinite(p) and np.isfinite(r)
    if abs(sx) > 0.5 or abs(sy) > 0.5:
        assert p == 0.0  # zero outside the image support


def test_query_mean_matches_pndf_mass(glints_map):
    # the mean of the whole image times its area is the P-NDF mass inside the support (~1)
    r = range_mean(glints_map, [8.0, 8.0], 64.0, [-0.5, -0.5], [0.5, 0.5])
    assert r * 1.0 == pytest.approx(1.0, abs=0.05)


# -- invalid input -------------------------------------------------------------------------------


@pytest.mark.parametrize("nm,why", [
    (np.zeros((4, 4, 3)), "zero"),
    (NM * 1.5, "not unit"),
    (NM * [1, 1, -1], "below"),
    (NM[..., :2], "channels"),
    (NM[0], "2D"),
    (NM[:1], "one row"),
])
def test_bad_normal_maps_rejected(nm, why):
    expect_error(lambda: elements(nm), "normal_map")
    expect_error(lambda: pndf(nm, [0, 0], 1.0, [0, 0]), "normal_map")


def test_pndf_rejects_bad_arguments():
    expect_error(lambda: pndf(NM, [np.nan, 0], 1.0, [0, 0]), "center")
    expect_error(lambda: pndf(NM, [0, 0], -1.0, [0, 0]), "sigma_p")
    expect_error(lambda: pndf(NM, [0, 0], np.inf, [0, 0]), "sigma_p")
    expect_error(lambda: pndf(NM, [0, 0], 1.0, [0, 0], 0.0), "intrinsic_roughness")
    expect_error(lambda: pndf(NM, [0, 0], 1.0, [0, 0, 0]), "s")
    # batch shapes that do not broadcast: was numpy's ValueError
    expect_error(lambda: pndf(NM, np.zeros((3, 2)), 1.0, np.zeros((4, 2))), "center")
    expect_error(lambda: pndf_image(NM, np.zeros((3, 2)), np.ones(4)), "center")
    expect_error(lambda: pndf_image(NM, [0, 0], 1.0, 0), "resolution")
    expect_error(lambda: pndf_image(NM, [0, 0], 1.0, 8, 1.5), "support")
    # precomputed elements of the wrong shape: was an out-of-bounds read in the kernel
    expect_error(lambda: pndf(NM, [0, 0], 1.0, [0, 0], elements_=(ELEM[0][:, :, :1], ELEM[1])),
                 "elements_")
    expect_error(lambda: pndf(NM, [0, 0], 1.0, [0, 0], elements_=ELEM[0]), "elements_")
    expect_error(lambda: hemisphere_ndf([1.0], [0.0, 1.0]), "m")


def test_queries_reject_bad_arguments(glints_map):
    gm = glints_map
    expect_error(lambda: point("map.npz", [0, 0], 1.0, [0, 0]), "gm")
    expect_error(lambda: point(gm, [0, np.nan], 1.0, [0, 0]), "center")
    expect_error(lambda: point(gm, [0, 0], -1.0, [0, 0]), "sigma_p")
    expect_error(lambda: point(gm, [0, 0], 1.0, [0, np.inf]), "s")
    expect_error(lambda: point(gm, np.zeros((3, 2)), 1.0, np.zeros((4, 2))), "center")
    expect_error(lambda: range_mean(gm, [0, 0], 1.0, [0, 0], [0, 0]), "s_max")
    expect_error(lambda: block_means(gm, np.array([10**9])), "image")
    expect_error(lambda: block_means(gm, np.array([0.5])), "image")


def test_integer_normal_maps_need_decoding():
    rgb = np.round((NM + 1) / 2 * 255).astype(np.uint8)
    expect_error(lambda: elements(rgb), "decode_normals")
    from prefilter.texture import decode_normals

    # the decoded map is accepted and close to the float one (8-bit quantisation)
    s, _ = elements(decode_normals(rgb, "directx"))
    assert np.abs(s - ELEM[0]).max() < 2.0 / 255 + 1e-9


def test_samplers_reject_negative_seeds(glints_map):
    # was NumPy's "expected non-negative integer" ValueError
    from prefilter.glints import sample_s, sample_wi

    expect_error(lambda: sample_s(glints_map, [0, 0], 1.0, -3), "rng")
    expect_error(lambda: sample_wi(glints_map, [0, 0], 1.0, [0, 0, 1.0], -3), "rng")
