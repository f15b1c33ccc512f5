"""Displaced reference under environment light: flat-surface closed forms and a narrow sun
against the (independently tested) directional-light ray marcher."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.leadr.displaced import (EnvSampler, displaced_env_radiance, displaced_radiance,
                                       naive_env_radiance, normal_mapped_env_radiance)
from prefilter.leadr.envmap import EnvMap, texel_directions
from prefilter.microfacet import Beckmann
from prefilter.texture import height_map

WO = np.array([0.5, 0.1, 0.8]) / np.linalg.norm([0.5, 0.1, 0.8])


def linear_env(rows=64):
    d, _ = texel_directions(rows, 2 * rows)
    return EnvMap(np.repeat(1.5 + d[..., :1] + 0.5 * d[..., 2:], 3, -1))


def test_flat_specular_under_constant_env_is_the_albedo():
    env = EnvMap(np.ones((32, 64, 3)))
    r = displaced_env_radiance(np.zeros((32, 32)), 16, 0, 0, WO, env, k=32, spp=8)
    assert r[0] == pytest.approx(float(Beckmann.isotropic(np.sqrt(2) * 0.1).albedo(WO)), rel=0.01)


def test_flat_diffuse_under_linear_env_is_the_closed_form():
    # integral (1.5 + w_x + 0.5 w_z) max(0, w_z) dw / pi = 1.5 + (2/3) 0.5
    h0 = np.zeros((32, 32))
    for f in (displaced_env_radiance, normal_mapped_env_radiance):
        r = f(h0, 16, 0, 0, WO, linear_env(), k=32, spp=8, specular=False)
        assert r[0] == pytest.approx(1.5 + 1.0 / 3.0, rel=0.01)
    r = naive_env_radiance(h0, 16, 0, 0, WO, linear_env(), samples=4096, specular=False)
    assert r[0] == pytest.approx(1.5 + 1.0 / 3.0, rel=0.01)


@pytest.mark.parametrize("specular", [False, True])
def test_narrow_sun_matches_the_directional_reference(specular):
    # A unit-integral sun of angular radius ~0.02 rad acts as a directional light; masking and
    # shadowing by the rough height field must agree with displaced_radiance (shadow rays).
    light = np.array([-0.8, 0.2, 0.45]) / np.linalg.norm([-0.8, 0.2, 0.45])
    d, om = texel_directions(256, 512)
    sun = np.exp(3000.0 * (d @ light - 1.0))
    env = EnvMap(np.repeat(sun[..., None], 3, -1) / np.sum(sun * om))
    h = height_map("gaussian", size=64, seed=0, corr_length=4.0,
                   rms_slope=0.5 * np.sqrt(2)).height
    a = displaced_env_radiance(h, 16, 0, 0, WO, env, k=48, spp=16, specular=specular)
    b = displaced_radiance(h, 16, 0, 0, WO, light, k=48, specular=specular)
    assert a[0] == pytest.approx(b, rel=0.02)
    # without shadow rays the result must be brighter (the test can tell shadowing apart)
    c = displaced_env_radiance(h, 16, 0, 0, WO, env, k=48, spp=16, specular=specular,
                               shadowing=False)
    assert c[0] > 1.01 * a[0]


def test_env_sampler_density_integrates_to_one_and_matches_samples():
    env = EnvMap(np.random.default_rng(1).random((16, 32, 3)) ** 4)
    s = EnvSampler(env)
    d, om = texel_directions(16, 32)
    assert np.sum(s.pdf(d.reshape(-1, 3)) * om.ravel()) == pytest.approx(1.0, rel=1e-9)
    w, p = s.sample(np.random.default_rng(2).random((20000, 3)))
    np.testing.assert_allclose(p, s.pdf(w), rtol=1e-9)
    # importance-sampled estimate of the total solid angle
    assert np.mean(1.0 / p) == pytest.approx(4 * np.pi, rel=0.03)


def test_deterministic_and_validated():
    h = height_map("gaussian", size=32, seed=0, corr_length=4.0, rms_slope=0.3).height
    env = linear_env(16)
    a = displaced_env_radiance(h, 8, 0, 0, WO, env, k=8, spp=4, seed=3)
    assert np.array_equal(a, displaced_env_radiance(h, 8, 0, 0, WO, env, k=8, spp=4, seed=3))
    with pytest.raises(PrefilterError, match="env"):
        displaced_env_radiance(h, 8, 0, 0, WO, np.ones((4, 8, 3)))
    with pytest.raises(PrefilterError, match="wo"):
        displaced_env_radiance(h, 8, 0, 0, [1.0, 0.0, 0.0], env)


def test_rotated_environment_points():
    # local z (the flat surface's normal) is map +x: E = pi (1.5 + 2/3 * 1) for L = 1.5 + w_x
    from prefilter.leadr.displaced import displaced_env_points

    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # columns: local axes
    d, _ = texel_directions(64, 128)
    env = EnvMap(np.repeat(1.5 + d[..., :1] + 0.0 * d[..., 2:], 3, -1))
    x, y = np.meshgrid(np.arange(8.0), np.arange(8.0))
    r = displaced_env_points(np.zeros((16, 16)), x, y, WO, env, rot=rot, spp=16, specular=False)
    assert r[:, 0].mean() == pytest.approx(1.5 + 2.0 / 3.0, rel=0.01)
