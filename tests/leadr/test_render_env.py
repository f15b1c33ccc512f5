"""leadr-env / leadr-irradiance render methods: environment orientation, closed forms."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.leadr.render import (render_leadr_env, render_leadr_irradiance,
                                    render_leadr_irradiance_naive)
from prefilter.leadr.shading import env_specular, grid_normals, shadowing_ratio
from prefilter.microfacet.fresnel import schlick
from prefilter.render import gbuffer, load_scene
from prefilter.render.methods import RenderSettings, describe, get_method, method_params

ROWS = 64
SIMPLIFIED = RenderSettings(params={"algorithm": "simplified"})


def doc_direction(u, v):
    """World direction of lat-long (u, v) as docs/leadr.md states it (written independently of
    the implementation): u = 0 -> +z, 1/4 -> -x, 1/2 -> -z, 3/4 -> +x; v = 0 -> +y."""
    phi, theta = 2 * np.pi * u, np.pi * v
    return np.stack(np.broadcast_arrays(-np.sin(theta) * np.sin(phi), np.cos(theta),
                                        np.sin(theta) * np.cos(phi)), -1)


def direction_image(rows=ROWS):
    """rgb = 1.5 + (d_x, d_y, d_z): every channel is linear in the world direction."""
    v = (np.arange(rows) + 0.5) / rows
    u = (np.arange(2 * rows) + 0.5) / (2 * rows)
    d = doc_direction(u[None, :], v[:, None])
    return 1.5 + d


def scene(tmp_path, material, image=None, lights=(), **cam):
    path = tmp_path / "env.npy"
    np.save(path, direction_image() if image is None else image)
    camera = {"origin": [0.3, 1.2, 2.5], "target": [0, 0, -0.3], "fov": 50, "width": 20,
              "height": 14, **cam}
    return load_scene({
        "camera": camera,
        "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [8, 8],
                     "material": material},
                    {"type": "sphere", "center": [1.2, 0.5, -1.0], "radius": 0.5,
                     "material": material}],
        "lights": [{"type": "environment", "image": "env.npy"}, *lights]}, base_dir=tmp_path)


def test_mirror_reflects_the_documented_direction(tmp_path):
    s = scene(tmp_path, {"alpha": 0.002, "f0": 1.0, "base_color": 0.0})
    img = render_leadr_env(s, RenderSettings())
    g = gbuffer(s)
    v, n = g.view, g.normal
    r = 2 * np.sum(v * n, -1, keepdims=True) * n - v
    expect = np.where(g.hit[..., None], 1.5 + r, 0.0)
    assert g.hit.sum() > 100
    np.testing.assert_allclose(img, expect, atol=0.02)


def test_diffuse_irradiance_of_a_linear_environment(tmp_path):
    # E(n) = integral (1.5 + d.a) max(0, n.d) dd = 1.5 pi + (2 pi / 3) n.a: radiance rho E / pi.
    rho = np.array([0.8, 0.5, 0.3])
    s = scene(tmp_path, {"alpha": 0.002, "f0": 0.0, "base_color": rho.tolist()})
    g = gbuffer(s)
    flip = np.where(np.sum(g.view * g.normal, -1) < 0, -1.0, 1.0)[..., None]
    expect = rho * (1.5 + 2.0 / 3.0 * g.normal * flip)
    expect = np.where(g.hit[..., None], expect, 0.0)
    for render in (render_leadr_irradiance, render_leadr_irradiance_naive):
        np.testing.assert_allclose(render(s, RenderSettings()), expect, atol=5e-3)
    # leadr-env adds the specular layer: f0 = 0 still reflects (1 - c)^5 of the mirror image.
    spec = render_leadr_env(s, RenderSettings()) - expect
    assert np.all(spec[g.hit] >= -5e-3) and spec[g.hit].max() > 0.01


def test_constant_environment_is_reproduced_by_rough_height_maps(tmp_path):
    # Simplified Algorithms 1 and 3 (leadr-env with algorithm=simplified) normalise by the
    # projected-area sum: a constant environment L gives f0 L + rho L exactly, whatever the
    # roughness, view or footprint (grazing included).
    mat = {"alpha": 0.3, "f0": 1.0, "base_color": 0.25,
           "height_map": {"procedural": "gaussian", "size": 64, "rms_slope": 0.6, "scale": 1.0}}
    from prefilter.leadr.render import _render_env

    s = scene(tmp_path, mat, image=np.full((16, 32, 3), 2.0), origin=[0.0, 0.3, 3.0])
    g = gbuffer(s)
    naive = lambda sc, st: _render_env(sc, st, False, "naive", shadowing=False)  # noqa: E731
    for render in (lambda sc, st: render_leadr_env(sc, SIMPLIFIED), naive):
        img = render(s, RenderSettings())
        np.testing.assert_allclose(img[g.hit], 2.0 * 1.25, rtol=2e-3)
        assert np.all(img[~g.hit] == 0)


def test_directional_light_is_shaded_exactly_not_through_sh(tmp_path):
    # A black environment plus one directional light along the normal of a smooth plane:
    # E = 2 <n, wl> exactly (an order-2 SH of the light would give 2 * 1.0 only up to ~5%, and
    # sphere pixels facing away from it would get the SH ringing instead of 0).
    rho = 0.5
    wl = np.array([0.0, 1.0, 0.0])
    s = scene(tmp_path, {"alpha": 0.002, "f0": 0.0, "base_color": rho},
              image=np.zeros((8, 16, 3)),
              lights=[{"type": "directional", "direction": (-wl).tolist(), "irradiance": 2.0}])
    g = gbuffer(s)
    img = render_leadr_irradiance(s, RenderSettings())
    flip = np.where(np.sum(g.view * g.normal, -1) < 0, -1.0, 1.0)[..., None]
    cos = np.maximum(np.sum(g.normal * flip * wl, -1), 0.0)
    expect = np.where(g.hit, rho * 2.0 * cos / np.pi, 0.0)
    np.testing.assert_allclose(img[..., 0], expect, rtol=2e-3, atol=1e-3)


def test_quads_rejected_and_deterministic(tmp_path):
    mat = {"alpha": 0.2, "f0": 0.04, "base_color": 0.3,
           "height_map": {"procedural": "anisotropic", "size": 64, "scale": 1.0}}
    s = scene(tmp_path, mat)
    a = render_leadr_env(s, RenderSettings())
    assert np.array_equal(a, render_leadr_env(s, RenderSettings()))
    assert np.all(np.isfinite(a))
    d = s.to_dict()
    d["lights"].append({"type": "quad", "radiance": 1.0, "vertices":
                        [[-1, 1, -1], [1, 1, -1], [1, 2, -1], [-1, 2, -1]]})
    with pytest.raises(PrefilterError, match="leadr-env"):
        render_leadr_env(load_scene(d, base_dir=tmp_path), RenderSettings())


def algorithm_1_numpy(env, wo, mean, cov, n, *, f0=None) -> np.ndarray:
    """Algorithm 1 with self-shadowing in NumPy, ``(P, C)`` (the compiled kernel is tested
    against it): Simplified Algorithm 1's grid and per-sample LOD, each sample weighted by
    ``G2 / G1`` (0 below the geometric plane); the projected-area sum stands for
    ``(n_bar.g / n_bar.o) / (1 + Lambda(wo))`` (supplemental eq. 10). No artificial micronormal:
    ``wo``, ``mean`` must give a grid that sees something."""
    m, w, cell = grid_normals(mean, cov, n)
    dot = np.einsum("pkj,pj->pk", m, wo)
    area = w * np.maximum(dot, 0.0) / m[..., 2]
    wi = 2.0 * dot[..., None] * m - wo[:, None, :]
    jac = 4.0 * np.abs(dot) * np.abs(m[..., 2]) ** 3
    with np.errstate(divide="ignore"):
        lod = 0.5 * np.log2(np.maximum(jac * cell[:, None], 1e-300) / env.texel_solid_angle)
    rad = env.lookup(wi, lod)
    if f0 is not None:
        rad = rad * schlick(np.asarray(f0)[:, None, None], dot[..., None])
    g = shadowing_ratio(np.broadcast_to(wo[:, None, :], wi.shape), wi, mean[:, None],
                        np.asarray(cov)[:, None])
    return np.einsum("pk,pkc->pc", area * g, rad) / area.sum(axis=1)[:, None]


def test_shadowed_specular_under_constant_env_is_the_beckmann_albedo():
    # With L = 1 and F = 1, Algorithm 1 with shadowing is the VNDF expectation of G2 / G1, i.e.
    # the directional albedo of the non-centred Beckmann microsurface (its own quadrature).
    from prefilter.leadr.envmap import EnvMap
    from prefilter.microfacet import Beckmann

    rng = np.random.default_rng(4)
    p = 6
    cz = rng.uniform(0.3, 0.95, p)
    ph = rng.uniform(0, 2 * np.pi, p)
    wo = np.stack([np.sqrt(1 - cz**2) * np.cos(ph), np.sqrt(1 - cz**2) * np.sin(ph), cz], -1)
    mu = rng.normal(scale=0.1, size=(p, 2))
    sd = rng.uniform(0.1, 0.5, (p, 2))
    r = rng.uniform(-0.5, 0.5, p)
    cov = np.stack([np.stack([sd[:, 0]**2, r * sd[:, 0] * sd[:, 1]], -1),
                    np.stack([r * sd[:, 0] * sd[:, 1], sd[:, 1]**2], -1)], -2)
    got = algorithm_1_numpy(EnvMap(np.ones((8, 16, 3))), wo, mu, cov, 33)[:, 0]
    want = [float(Beckmann(mu[i], cov[i]).albedo(wo[i])) for i in range(p)]
    np.testing.assert_allclose(got, want, rtol=0.01)
    assert min(want) < 0.97  # shadowing is visible in these configurations


def test_compiled_shadowed_kernel_equals_the_numpy_algorithm_1():
    from prefilter.leadr.envmap import EnvMap, procedural_env

    env = EnvMap(procedural_env(32))
    rng = np.random.default_rng(7)
    p = 200
    cz = rng.uniform(0.1, 1.0, p)
    ph = rng.uniform(0, 2 * np.pi, p)
    wo = np.stack([np.sqrt(1 - cz**2) * np.cos(ph), np.sqrt(1 - cz**2) * np.sin(ph), cz], -1)
    mu = rng.normal(scale=0.2, size=(p, 2))
    cov = np.broadcast_to([[0.09, 0.02], [0.02, 0.05]], (p, 2, 2))
    a = env_specular(env, wo, mu, cov, 9, shadowing=True)
    b = algorithm_1_numpy(env, wo, mu, cov, 9)
    # the compiled kernel keeps the artificial micronormal (weight 1e-5) in the sum
    np.testing.assert_allclose(a, b, rtol=2e-3, atol=1e-4 * b.max())
    assert np.mean(a) < 0.97 * np.mean(env_specular(env, wo, mu, cov, 9))


def test_diffuse_shadowing_matches_the_exact_shadowed_irradiance():
    # SH diffuse + correction vs Algorithm 3 with the level-0 quadrature of the paper's
    # Algorithm 2 irradiance (G2 / G1 per light direction), relative to the shadowed radiance.
    from prefilter.studies.leadr import diffuse_exact
    from prefilter.leadr.envmap import EnvMap, procedural_env
    from prefilter.leadr.shading import diffuse_shadowing

    env = EnvMap(procedural_env(64))
    rng = np.random.default_rng(8)
    p = 12
    cz = rng.uniform(0.2, 1.0, p)
    ph = rng.uniform(0, 2 * np.pi, p)
    wo = np.stack([np.sqrt(1 - cz**2) * np.cos(ph), np.sqrt(1 - cz**2) * np.sin(ph), cz], -1)
    mu = rng.normal(scale=0.15, size=(p, 2))
    cov = np.array([[0.25, 0.05], [0.05, 0.16]])
    corr = diffuse_shadowing(env, wo, mu, cov, 5)
    for i in range(p):
        full = diffuse_exact(env, wo[i], mu[i], cov, 5, shadowing=True)
        plain = diffuse_exact(env, wo[i], mu[i], cov, 5)
        np.testing.assert_allclose(plain + corr[i], full, rtol=0, atol=0.01 * full.max())
        assert np.all(full < 0.97 * plain)  # the correction is not negligible here


def test_shadowed_method_render(tmp_path):
    # smooth surface: no shadowing, same image as the simplified algorithms (direction map,
    # rgb f0)
    s = scene(tmp_path, {"alpha": 0.002, "f0": [0.9, 0.5, 0.2], "base_color": 0.1})
    np.testing.assert_allclose(render_leadr_env(s, RenderSettings()),
                               render_leadr_env(s, SIMPLIFIED), rtol=1e-3, atol=1e-4)
    # rough height map under a constant sky: never brighter than the unshadowed 1, finite
    mat = {"alpha": 0.3, "f0": 1.0, "base_color": 0.0,
           "height_map": {"procedural": "gaussian", "size": 64, "rms_slope": 0.6, "scale": 1.0}}
    s = scene(tmp_path, mat, image=np.ones((16, 32, 3)), origin=[0.0, 0.3, 3.0])
    g = gbuffer(s)
    img = render_leadr_env(s, RenderSettings())
    assert np.all(np.isfinite(img)) and np.all(img[g.hit] <= 1.0 + 1e-9)
    assert img[g.hit].min() < 0.9


def test_algorithm_is_a_setting_of_the_registered_methods():
    for name in ("leadr-env", "leadr-env-naive", "leadr-irradiance", "leadr-irradiance-naive"):
        assert method_params(name) == {"algorithm": ("full", "simplified")}
        assert describe(name)
    assert get_method("leadr-env") is render_leadr_env
    for gone in ("leadr-env-shadowed", "leadr-env-simplified"):
        with pytest.raises(PrefilterError, match="method"):
            get_method(gone)
