"""Texture layouts, the GLSL lookup's Python twin, and the error half floats add."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from glsl_numpy import aniso_glsl_twin as glsl_twin
from glsl_numpy import load_layout
from prefilter.ltc.aniso.export import export_all, glsl_source, texture_layout, texture_params
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral, polygon_integral_minv
from prefilter.ltc.validate import random_quads


def configs(n, seed):
    rng = np.random.default_rng(seed)
    t = np.radians(rng.uniform(0, 89, n))
    p = rng.uniform(-np.pi, np.pi, n)
    wo = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    return wo, rng.uniform(0.01, 1, n), rng.uniform(0.01, 1, n)


def test_twin_matches_lookup(table):
    wo, ax, ay = configs(3000, 0)
    tex = texture_layout(table, np.float64)
    Minv, n, f5 = glsl_twin(tex, texture_params(table), wo, ax, ay)
    M, mag, fr = table.lookup(wo, ax, ay)
    # the adjugate is det(M) M^-1: compare M^-1 up to that positive factor
    ref = np.linalg.inv(M)
    scale = np.linalg.det(M)[:, None, None]
    np.testing.assert_allclose(Minv / scale, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(n, mag, rtol=1e-10)
    np.testing.assert_allclose(f5, fr, rtol=1e-10, atol=1e-14)


def test_layout_channels(table):
    tex = texture_layout(table)
    T, F, A, R = table.shape
    assert tex.shape == (3, R * A, F, T, 4) and tex.dtype == np.float32
    i = (5, 2, 6, 3)  # (theta, phi, alpha, ratio)
    texel = tex[:, i[3] * A + i[2], i[1], i[0]].reshape(-1)
    np.testing.assert_allclose(texel[:9], table.M[i].reshape(-1), rtol=1e-6)
    assert texel[9] == pytest.approx(table.magnitude[i], rel=1e-6)


def test_half_float_error(table):
    """Shading with the half-float layout vs float64: well under 0.5 percentage points."""
    wo, ax, ay = configs(4000, 1)
    ax, ay = 0.05 + 0.95 * ax, 0.05 + 0.95 * ay
    quads = clip_to_horizon(random_quads(4000, np.random.default_rng(2)))
    p = texture_params(table)
    full = []
    for dt in (np.float64, np.float16):
        Minv, n, _ = glsl_twin(texture_layout(table, dt), p, wo, ax, ay)
        full.append(n * polygon_integral_minv(Minv, quads))
    ok = full[0] > 1e-3
    rel = np.abs(full[1] - full[0])[ok] / full[0][ok]
    assert np.median(rel) < 0.005 and np.percentile(rel, 90) < 0.005, (
        np.median(rel), np.percentile(rel, 90))
    # and the twin (float64) reproduces lookup + polygon_integral
    M, mag, _ = table.lookup(wo, ax, ay)
    np.testing.assert_allclose(full[0], mag * polygon_integral(M, quads), rtol=1e-8, atol=1e-14)


def test_export_files(tmp_path, table):
    paths = export_all(table, tmp_path)
    names = {p.name for p in paths}
    assert {"ggx_aniso_f32.npz", "ggx_aniso_f16.npz", "ggx_aniso_f32.bin", "ltc_aniso.glsl",
            "ggx_aniso_layout.json"} <= names
    tex = load_layout(tmp_path / "ggx_aniso_f16.npz")
    assert tex.dtype == np.float16
    raw = np.fromfile(tmp_path / "ggx_aniso_f32.bin", "<f4").reshape(tex.shape)
    np.testing.assert_array_equal(raw, texture_layout(table))
    src = glsl_source(table)
    assert "void ltcAnisoLookup(vec3 wo, float ax, float ay" in src and "{" in src
    assert src.count("{") == src.count("}")


def test_layout_needs_uniform_axes(table):
    from prefilter.ltc import AnisoGGXTable

    axes = list(table.axes)
    axes[0] = axes[0] ** 1.5 / axes[0][-1] ** 0.5
    with pytest.raises(PrefilterError, match="uniform"):
        texture_params(AnisoGGXTable(axes, table.M, table.magnitude, table.fresnel))
