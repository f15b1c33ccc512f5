"""Grid integrators vs Monte Carlo with exact visible normals; SH irradiance vs quadrature;
artificial micronormal (no NaN, never black)."""

import numpy as np
import pytest

from prefilter.leadr import (EnvMap, diffuse_directional, diffuse_sh, env_specular, gaussian_grid,
                             procedural_env, sh9_irradiance, sh9_project)
from prefilter.leadr.envmap import texel_directions
from prefilter.leadr.shading import _grid_integrate
from prefilter.microfacet.fresnel import schlick
from prefilter.microfacet import Beckmann


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _smooth(w):
    """A smooth RGB radiance: a broad warm lobe plus a linear gradient (positive everywhere)."""
    a = np.exp(3.0 * (w @ _unit([0.4, -0.2, 0.9]) - 1.0))
    return np.stack([1.0 + 4 * a, 1.2 + 0.5 * w[..., 0], 0.8 + 0.3 * w[..., 2]], -1)


def test_paper_grid_weights_and_derived_spacing():
    p, w, h = gaussian_grid(5, 0.9)
    np.testing.assert_allclose(w, [0.0725, 0.2443, 0.3663, 0.2443, 0.0725], atol=5e-5)
    np.testing.assert_allclose(p, [-1.8, -0.9, 0, 0.9, 1.8])
    for n in (3, 5, 9, 17, 33, 128):
        p, w, h = gaussian_grid(n)
        assert abs(np.sum(w * p * p) + h * h / 12 - 1) < 1e-10 and abs(np.sum(w * p)) < 1e-12


VIEWS = [((0.1, -0.05), ((0.02, 0.005), (0.005, 0.01)), (0.3, 0.1, 0.95)),
         ((-0.2, 0.1), ((0.0625, 0.0), (0.0, 0.0625)), (-0.5, 0.2, 0.8))]


@pytest.mark.parametrize("mu,cov,wo", VIEWS)
def test_env_specular_converges_to_visible_normal_monte_carlo(mu, cov, wo):
    # Simplified Algorithm 1 computes E_vndf[F L(reflect(wo, m))] (no self-shadowing).
    wo = _unit(wo)
    size = 128
    d, _ = texel_directions(size, 2 * size)
    env = EnvMap(_smooth(d))
    grid = env_specular(env, wo, mu, cov, 65, f0=0.2, lod_bias=-30.0)
    b = Beckmann(mu, cov)
    u = np.random.default_rng(5).random((400_000, 2))
    m = b.sample_vndf(wo, u)
    dot = m @ wo
    wi = 2 * dot[:, None] * m - wo
    f = 0.2 + 0.8 * (1 - dot) ** 5
    vals = f[:, None] * _smooth(wi)
    est, err = vals.mean(0), vals.std(0) / np.sqrt(len(vals))
    assert np.all(np.abs(grid - est) < 4 * err + 3e-3 * est), (grid, est, err)


@pytest.mark.parametrize("mu,cov,wo", VIEWS)
def test_diffuse_directional_converges_to_visible_normal_monte_carlo(mu, cov, wo):
    wo, wl = _unit(wo), _unit([0.5, 0.3, 0.7])
    grid = diffuse_directional(wo, wl, mu, cov, 33)
    m = Beckmann(mu, cov).sample_vndf(wo, np.random.default_rng(2).random((400_000, 2)))
    vals = np.maximum(m @ wl, 0) / np.pi
    est, err = vals.mean(), vals.std() / np.sqrt(len(vals))
    assert abs(grid - est) < 4 * err + 2e-3 * est, (grid, est, err)


@pytest.mark.parametrize("mu,cov,wo", VIEWS)
def test_shadowed_diffuse_directional_is_visible_normal_mc_times_smith_g2_over_g1(mu, cov, wo):
    # Algorithm 3 with Algorithm 2's shadowed irradiance for one light: the Lambertian
    # microsurface radiance E_vndf[<m, wl>] / pi * G2 / G1, with Lambda from the microfacet
    # module's own implementation (uncorrelated Smith G2).
    wo, wl = _unit(wo), _unit([-0.8, 0.4, 0.3])  # low light: shadowing is large
    grid = diffuse_directional(wo, wl, mu, cov, 33, shadowing=True)
    model = Beckmann(mu, cov)
    m = model.sample_vndf(wo, np.random.default_rng(3).random((400_000, 2)))
    lo, li = model.smith_lambda(wo), model.smith_lambda(wl)
    g = (1 + lo) / (1 + lo + li)
    vals = np.maximum(m @ wl, 0) / np.pi * g
    est, err = vals.mean(), vals.std() / np.sqrt(len(vals))
    assert abs(grid - est) < 4 * err + 2e-3 * est, (grid, est, err)
    assert g < 0.98 or cov[0][0] < 0.05  # visible shadowing on the rougher surface


def _irradiance_quadrature(radiance_fn, n, size=256):
    d, om = texel_directions(size, 2 * size)
    L = radiance_fn(d)
    return np.einsum("hw,hwc,nhw->nc", om, L, np.maximum(np.einsum("nk,hwk->nhw", n, d), 0.0))


def test_sh_irradiance_equals_quadrature_for_band_limited_radiance():
    def rad(w):  # spherical harmonics of order <= 2 only
        x, y, z = w[..., 0], w[..., 1], w[..., 2]
        return np.stack([1.5 + 0.8 * z + 0.4 * x * y, 1.0 - 0.3 * x + 0.5 * z * z,
                         0.7 + 0.2 * (x * x - y * y)], -1)

    n = _unit(np.random.default_rng(0).normal(size=(40, 3)))
    env = EnvMap(rad(texel_directions(128, 256)[0]))
    sh = sh9_irradiance(sh9_project(env), n)
    np.testing.assert_allclose(sh, _irradiance_quadrature(rad, n), rtol=2e-4)


def test_sh_irradiance_error_on_a_sharp_environment_is_small():
    # Order-2 SH keeps the irradiance of any environment within a few percent of its average
    # (Ramamoorthi & Hanrahan 2001); the procedural sky has a sun of 20x the sky radiance.
    env = EnvMap(procedural_env(128))
    n = _unit(np.random.default_rng(1).normal(size=(40, 3)))
    sh = sh9_irradiance(sh9_project(env), n)
    quad = _irradiance_quadrature(lambda w: procedural_env(128), n, 128)
    err = np.abs(sh - quad).max() / quad.mean()
    assert err < 0.1, err


def test_diffuse_sh_for_constant_radiance_is_the_radiance():
    env = EnvMap(np.full((16, 32, 3), 0.7))
    v = diffuse_sh(sh9_project(env), _unit([0.2, 0.3, 0.9]), (0.3, -0.2),
                   ((0.1, 0.02), (0.02, 0.05)), 9)
    # E = pi L for every micronormal, so the outgoing radiance is L (albedo 1).
    np.testing.assert_allclose(v, 0.7, rtol=2e-3)


def test_artificial_micronormal_no_nan_no_black():
    env = EnvMap(procedural_env(32))
    wo = _unit(np.array([[1, 0, 0], [1, 0, -0.3], [0, 0, -1.0], [-1, 0, 0.02], [0, 1, 1e-9]]))
    mu = np.array([0.0, 0.0])
    cov = np.eye(2) * 1e-6
    for m in (mu, np.array([3.0, 0.0]), np.array([-3.0, 1.0])):
        spec = env_specular(env, wo, m, cov, 5, f0=0.04)
        diff = diffuse_sh(sh9_project(env), wo, m, cov, 5)
        dirl = diffuse_directional(wo, _unit([0.0, 0.2, 1.0]), m, cov, 5)
        assert np.all(np.isfinite(spec)) and np.all(spec > 0)
        assert np.all(np.isfinite(diff)) and np.all(diff > 0)
        assert np.all(np.isfinite(dirl)) and np.all(dirl >= 0)


def _env_specular_twin(env, wo, mu, cov, n, f0, to_world):
    """Simplified Algorithm 1 in NumPy, on the grid integrator of the diffuse layers: each grid
    reflection read at the LOD of its solid angle, Schlick Fresnel of ``m.wi = m.wo``."""
    texel = env.texel_solid_angle

    def radiance(m, wi, jac, cell, tw):  # one chunk: the whole batch
        lod = 0.5 * np.log2(np.maximum(jac * cell, 1e-300) / texel)
        rad = env.lookup(np.einsum("pij,pkj->pki", tw, wi), lod)
        return rad if f0 is None else rad * schlick(f0, np.sum(m * wi, -1))[..., None]

    return _grid_integrate(wo, mu, cov, n, None, radiance, to_world)


def test_compiled_env_specular_matches_the_numpy_twin():
    env = EnvMap(procedural_env(32))
    rng = np.random.default_rng(4)
    wo = _unit(rng.normal(size=(200, 3)) + [0, 0, 1.5])
    wo[:5] = _unit(np.array([[1, 0, -0.2], [0, 0, -1.0], [1, 0, 0], [0.3, 0.2, 0.9], [0, 1, 0.01]]))
    mu = rng.normal(scale=0.4, size=(200, 2))
    a = rng.normal(scale=0.3, size=(200, 2, 2))
    cov = a @ np.swapaxes(a, -1, -2) + 1e-4 * np.eye(2)
    ang = rng.uniform(0, 2 * np.pi, 200)
    rot = np.zeros((200, 3, 3))
    c, s = np.cos(ang), np.sin(ang)
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = c, -s, s, c
    rot[:, 2, 2] = 1.0
    for n, f0 in ((5, 0.04), (9, None)):
        fast = env_specular(env, wo, mu, cov, n, f0=f0, to_world=rot)
        ref = _env_specular_twin(env, wo, mu, cov, n, f0, rot)
        np.testing.assert_allclose(fast, ref, rtol=1e-7, atol=1e-9)
