"""Roughness per mip level against closed forms: a map of two normals at +-theta (mean-normal
length cos(theta), slope variance tan^2(theta)), level sizes, roughness maps, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.multiscale.convolution import alpha_total
from prefilter.multiscale.meso import mean_resultant_length
from prefilter.roughness.bake import (
    METHODS,
    alpha_toksvig,
    as_normal_field,
    bake_roughness,
    load_normals,
)
from prefilter.texture.io import write_image
from prefilter.texture.normalmap import encode_normals
from prefilter.texture.procedural import normal_map


def two_normals(theta: float, size: int = 8) -> np.ndarray:
    """Columns alternate between (sin, 0, cos) and (-sin, 0, cos): every level >= 1 averages both
    equally (mean-normal length cos(theta), slopes +-tan(theta) along x)."""
    n = np.zeros((size, size, 3))
    n[..., 0] = np.where(np.arange(size) % 2 == 0, np.sin(theta), -np.sin(theta))
    n[..., 2] = np.cos(theta)
    return n


@pytest.mark.parametrize("theta", [0.1, 0.4, 0.8])
def test_toksvig_two_normals_closed_form(theta):
    c = np.cos(theta)
    levels = bake_roughness(two_normals(theta), 0.0, "toksvig")
    # alpha0 = 0: alpha'^2 = 2 sigma^2 / (1 + 2 sigma^2) with sigma^2 = (1 - c) / c
    want = np.sqrt(2.0 * (1.0 - c) / (2.0 - c))
    for a in levels[1:]:
        assert np.allclose(a, want, rtol=1e-12)


@pytest.mark.parametrize("alpha0", [0.05, 0.3, 0.7])
def test_toksvig_is_the_papers_exponent_factor(alpha0):
    # Toksvig 2005 eq. 3: s' = s r / (r + s (1 - r)), with s = 2 / alpha^2 - 2 both ways
    r = np.linspace(0.5, 1.0, 11)
    s = 2.0 / alpha0**2 - 2.0
    s_filtered = s * r / (r + s * (1.0 - r))
    assert np.allclose(alpha_toksvig(r, alpha0), np.sqrt(2.0 / (s_filtered + 2.0)), rtol=1e-12)


@pytest.mark.parametrize("theta,alpha0", [(0.1, 0.0), (0.3, 0.2), (0.6, 0.5)])
def test_lean_two_normals_closed_form(theta, alpha0):
    levels = bake_roughness(two_normals(theta), alpha0, "lean")
    want = np.sqrt(min(alpha0**2 + np.tan(theta) ** 2, 1.0))
    for a in levels[1:]:
        assert np.allclose(a, want, rtol=1e-12)


@pytest.mark.parametrize("theta", [0.1, 0.3, 0.6])
def test_ltc_two_normals_matches_mean_resultant_length(theta):
    # alpha_micro = 0: alpha_total = alpha_meso, whose LTC has mean resultant length cos(theta)
    alpha_meso = bake_roughness(two_normals(theta), 0.0, "ltc")[1]
    assert np.allclose(mean_resultant_length(alpha_meso), np.cos(theta), atol=1e-6)
    # alpha_micro > 0: eq. 7 of multiscale/convolution.py on top
    levels = bake_roughness(two_normals(theta), 0.25, "ltc")
    for a in levels[1:]:
        assert np.allclose(a, alpha_total(0.25, alpha_meso[0, 0]), rtol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_level_sizes_and_flat_maps(method):
    n = np.zeros((16, 4, 3))
    n[..., 2] = 1.0
    levels = bake_roughness(n, 0.3, method)
    assert [a.shape for a in levels] == [(16, 4), (8, 2), (4, 1), (2, 1), (1, 1)]
    for a in levels:  # no spread: every level keeps the base roughness
        assert np.allclose(a, 0.3, rtol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_level0_is_the_base_roughness_and_levels_grow(method):
    n = normal_map("gaussian", 32, seed=1)
    alpha = np.full((32, 32), 0.2)
    levels = bake_roughness(n, alpha, method)
    assert np.allclose(levels[0], 0.2, atol=1e-7)
    means = [a.mean() for a in levels]
    assert all(b > a for a, b in zip(means, means[1:]))


def test_roughness_map_is_averaged_in_alpha_squared():
    n = np.zeros((2, 2, 3))
    n[..., 2] = 1.0
    alpha = np.array([[0.1, 0.3], [0.5, 0.7]])
    for method in METHODS:
        top = bake_roughness(n, alpha, method)[1]
        assert np.allclose(top, np.sqrt(np.mean(alpha**2)), rtol=1e-12)


def test_bad_input():
    n = normal_map("gaussian", 16)
    with pytest.raises(PrefilterError, match="power-of-two"):
        bake_roughness(np.concatenate([n, n[:4]]), 0.1, name="map.png")
    with pytest.raises(PrefilterError, match="method"):
        bake_roughness(n, 0.1, "blinn")
    with pytest.raises(PrefilterError, match="normal map's size 16 x 16"):
        bake_roughness(n, np.full((8, 8), 0.1))
    with pytest.raises(PrefilterError, match=r"alpha in \[0, 1\]"):
        bake_roughness(n, 1.5)
    with pytest.raises(PrefilterError, match="not a normal map.*length"):
        as_normal_field(0.5 * n)
    down = n.copy()
    down[3, 3] = (0.0, 0.6, -0.8)
    with pytest.raises(PrefilterError, match="below the surface"):
        as_normal_field(down)


@pytest.mark.parametrize("convention", ["opengl", "directx"])
def test_load_normals_from_png(tmp_path, convention):
    n = normal_map("flakes", 16, seed=2)
    write_image(tmp_path / "n.png", encode_normals(n, convention), bits=16)
    got = load_normals(str(tmp_path / "n.png"), convention)
    assert np.allclose(got, n, atol=1e-4)


def test_load_normals_errors(tmp_path):
    with pytest.raises(PrefilterError, match="no such file"):
        load_normals(str(tmp_path / "missing.png"))
    rng = np.random.default_rng(0)
    write_image(tmp_path / "photo.png", rng.random((16, 16, 3)))
    with pytest.raises(PrefilterError, match="photo.png: not a normal map"):
        load_normals(str(tmp_path / "photo.png"))
    write_image(tmp_path / "grey.png", np.full((16, 16), 0.5))
    with pytest.raises(PrefilterError, match="not a normal map: expected 3 or 4 channels"):
        load_normals(str(tmp_path / "grey.png"))
    with pytest.raises(PrefilterError, match="procedural:KIND:SIZE"):
        load_normals("procedural:gaussian")
    assert load_normals("procedural:gaussian:8:3").shape == (8, 8, 3)
