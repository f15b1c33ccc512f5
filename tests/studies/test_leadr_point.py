"""Point-light acceptance pieces: the ray-traced reference's shadowing against Smith, the flat
closed forms, the box filter of the moments, and a tiny version of the image rows."""

import numpy as np
import pytest

from prefilter.leadr import point_light
from prefilter.studies.leadr import POINT_SURFACES, image_point
from prefilter.leadr.displaced import (cell_moments, displaced_point_radiance,
                                       normal_mapped_point_radiance, trace_points)
from prefilter.leadr.render import footprint_moments
from prefilter.microfacet import Beckmann
from prefilter.texture import MipChain, height_map


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_shadow_rays_give_smith_g2_over_g1_on_a_gaussian_height_field():
    # Smith (uncorrelated masking / shadowing, supplemental 1.5): among visible points, the
    # <m, wi>-weighted lit fraction is G2 / G1 = (1 + Lambda_o) / (1 + Lambda_o + Lambda_i),
    # with Lambda from the microfacet module (not from the ray marcher).
    h = np.ascontiguousarray(height_map("gaussian", size=128, seed=0, rms_slope=0.5,
                                        corr_length=4.0).height)
    m = cell_moments(h).reshape(-1, 5).mean(0)
    model = Beckmann([0.0, 0.0], [[m[2], m[4]], [m[4], m[3]]])
    rng = np.random.default_rng(2)
    x, y = rng.random(30_000) * 128, rng.random(30_000) * 128
    wo = _unit([0.0, 0.5, 0.87])
    wi = _unit([0.9, 0.1, 0.42])
    hit, n, lit = trace_points(h, x, y, wo, wi)
    c = np.maximum(n @ wi, 0.0) * hit
    frac = np.sum(c * lit) / np.sum(c)
    lo, li = float(model.smith_lambda(wo)), float(model.smith_lambda(wi))
    smith = (1 + lo) / (1 + lo + li)
    assert abs(frac - smith) < 0.01, (frac, smith)
    assert smith < 0.97  # shadowing is visible here
    # and the light below the mean plane lights nothing
    assert not np.any(trace_points(h, x[:100], y[:100], wo, _unit([0.9, 0.0, -0.1]))[2][
        trace_points(h, x[:100], y[:100], wo)[0]])


def test_flat_surface_point_radiance_is_the_closed_form():
    h = np.zeros((16, 16))
    rng = np.random.default_rng(3)
    x, y = rng.random(50) * 16, rng.random(50) * 16
    wo = _unit(np.stack([rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.5, 0.5, 50),
                         np.ones(50)], -1))
    wi = _unit(np.stack([rng.uniform(-0.8, 0.8, 50), rng.uniform(-0.8, 0.8, 50),
                         np.ones(50)], -1))
    spec = point_light(wo, wi, [0.0, 0.0], np.eye(2) * 0.01)
    for f in (displaced_point_radiance, normal_mapped_point_radiance):
        np.testing.assert_allclose(f(h, x, y, wo, wi, sigma_b=0.1), spec, rtol=1e-9)
        np.testing.assert_allclose(f(h, x, y, wo, wi, specular=False, albedo=0.5),
                                   0.5 / np.pi * wi[:, 2], rtol=1e-9)


def test_footprint_moments_are_the_box_average_over_the_pixel():
    rng = np.random.default_rng(4)
    a = rng.random((64, 64, 5))
    chain = MipChain(a)
    # a texel-aligned 16 x 16 footprint: exactly the plain average of those texels
    d = np.array([[[16 / 64, 0.0], [0.0, 16 / 64]]])
    got = footprint_moments(chain, np.array([[0.5, 0.5]]), d)[0]
    np.testing.assert_allclose(got, a[24:40, 24:40].reshape(-1, 5).mean(0), rtol=1e-12)
    # a 24 x 40 one: within 0.004 of the box average (values in [0, 1]); one trilinear tap of
    # the major axis' size is not (the test can tell)
    d = np.array([[[24 / 64, 0.0], [0.0, 40 / 64]]])
    box = a[12:52, 20:44].reshape(-1, 5).mean(0)
    taps = footprint_moments(chain, np.array([[0.5, 0.5]]), d)[0]
    one = footprint_moments(chain, np.array([[0.5, 0.5]]), d, max_taps=1)[0]
    assert np.abs(taps - box).max() < 0.004 < np.abs(one - box).max()


@pytest.fixture(scope="module")
def tiny_rows():
    return image_point(surfaces={"iso 0.25": POINT_SURFACES["iso 0.25"]}, shapes=("plane",),
                       texels_per_pixel=(8.0,), width=12, height=9, sub=8, jitters=2,
                       tex_size=64, noise_floor=True, log=lambda r: None)


def test_tiny_image_rows_leadr_beats_naive_against_the_displaced_reference(tiny_rows):
    spec, diff = tiny_rows
    assert spec["shading"] == "specular" and diff["shading"] == "diffuse"
    for r in tiny_rows:
        assert r["pixels"] > 50 and r["ref noise"] < 0.2
        assert all(np.isfinite(v) for k, v in r.items() if k.startswith(("rmse", "flip")))
        assert "flicker leadr" in r
    # naive misses the meso roughness: several times off for specular
    assert spec["rmse leadr"] < 0.5 * spec["rmse naive"]
    assert diff["rmse leadr"] < diff["rmse naive"]


def test_tiny_rows_leadr_point_method_and_flicker_floor(tiny_rows):
    """``leadr-point``'s shading (box filter + ``G2 / G1`` diffuse, what the method renders)
    against the displaced reference: < 0.5x naive specular, < naive diffuse, and closer than the
    old one-tap unshadowed diffuse; the reference's own sampling floor is below every method's
    flicker score (a score is ~ sqrt(own^2 + floor^2))."""
    spec, diff = tiny_rows
    assert spec["rmse leadr-point"] < 0.5 * spec["rmse naive"]
    assert diff["rmse leadr-point"] < diff["rmse naive"]
    assert diff["rmse leadr-point"] < diff["rmse leadr one tap"]
    for r in tiny_rows:
        assert 0.0 < r["flicker floor"] < r["ref noise"]
        for m in ("leadr", "leadr-point", "naive", "normal-mapped"):
            assert r["flicker floor"] < r[f"flicker {m}"], (m, r)
            assert np.isfinite(r[f"flicker2 {m}"])
