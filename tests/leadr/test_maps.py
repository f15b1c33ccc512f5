"""Moment maps: slope convention, mips = box averages, PSD shading statistics, bake command."""

import json

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.leadr import moments, shading_stats, slopes_from_height, slopes_from_normals
from prefilter.leadr.io import read_moment_exr


def _box(a, level):
    k = 2**level
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def test_slope_sign_convention_on_a_ramp():
    # h = 0.3 x - 0.2 y rises along +x: slope (0.3, -0.2); its normal tilts towards -x.
    yy, xx = np.mgrid[0:16, 0:16].astype(float)
    s = slopes_from_height(0.3 * xx - 0.2 * yy)
    np.testing.assert_allclose(s[2:-2, 2:-2], np.broadcast_to([0.3, -0.2], (12, 12, 2)), atol=1e-12)
    n = np.array([-0.3, 0.2, 1.0]) / np.linalg.norm([-0.3, 0.2, 1.0])
    np.testing.assert_allclose(slopes_from_normals(n), [0.3, -0.2], atol=1e-12)


def test_texel_size_scales_slopes_of_a_sine():
    n, t = 64, 0.5
    x = np.arange(n) * t
    h = np.broadcast_to(np.sin(2 * np.pi * x / (n * t)), (n, n))
    s = slopes_from_height(h, texel_size=t)
    exact = 2 * np.pi / (n * t) * np.cos(2 * np.pi * x / (n * t))
    # Central differences: relative error (k t)^2 / 6.
    np.testing.assert_allclose(s[0, :, 0], exact, atol=2e-3 * np.abs(exact).max())
    np.testing.assert_allclose(s[..., 1], 0.0, atol=1e-12)


@pytest.mark.parametrize("kind", ["height", "normals", "slopes"])
def test_each_mip_is_the_box_average_of_level0(kind):
    rng = np.random.default_rng(1)
    h = rng.normal(size=(32, 16))
    s = slopes_from_height(h)
    data = {"height": h, "slopes": s,
            "normals": np.concatenate([-s, np.ones(s.shape[:2] + (1,))], -1) * 2.5}[kind]
    maps = moments(data)
    x, y = s[..., 0], s[..., 1]
    level0 = np.stack([x, y, x * x, y * y, x * y], -1)
    np.testing.assert_allclose(maps.chain.levels[0], level0, rtol=1e-12, atol=1e-12)
    for lv in range(1, 5):
        np.testing.assert_allclose(maps.chain.levels[lv], _box(level0, lv), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("band_rows", [1, 4, 16, 64])
def test_banded_levels_are_the_bytes_of_the_whole_map(band_rows):
    """Bands of rows as independent tasks (``band_rows``, ``map_fn``) give every level bit for
    bit, including the levels below the bands' depth and a map wider than tall."""
    rng = np.random.default_rng(2)
    h = rng.normal(size=(32, 64))
    whole = moments(h).chain.levels
    calls = []

    def counting_map(f, *its):
        calls.append(len(its[0]))
        return map(f, *its)

    banded = moments(h, band_rows=band_rows, map_fn=counting_map).chain.levels
    assert len(banded) == len(whole) == 7
    for a, b in zip(whole, banded):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()
    assert calls == ([32 // band_rows] if band_rows < 32 else [])


def test_band_rows_must_be_a_power_of_two():
    with pytest.raises(PrefilterError, match="band_rows: expected a power of two"):
        moments(np.zeros((16, 16)), band_rows=3)


def test_top_level_covariance_matches_the_gaussian_surface():
    from prefilter.texture import height_map

    cov = np.array([[0.04, 0.01], [0.01, 0.02]])
    hm = height_map("anisotropic", size=256, seed=3, cov=cov, corr_length=4.0)
    maps = moments(hm, base_roughness=0.1)
    mean, c = maps.lookup(np.array([0.5, 0.5]), lod=maps.chain.n_levels - 1)
    np.testing.assert_allclose(mean, 0.0, atol=1e-10)
    # The generator matches the discrete process's covariance; an instance has sampling error.
    np.testing.assert_allclose(c, cov + 0.01 * np.eye(2), atol=0.006)


def test_shading_covariance_is_never_negative_on_adversarial_moments():
    rng = np.random.default_rng(7)
    r = 0.05
    m = rng.normal(size=(20000, 5)) * np.array([3, 3, 1, 1, 2])
    # Adversarial cases: E[x^2] < E[x]^2, |c_xy| > sqrt(c_xx c_yy), huge means (cancellation),
    # float16 quantisation of valid moments.
    big = np.array([[1e4, -1e4, 1e8, 1e8 - 1.0, -1e8 + 3.0]])
    s = rng.normal(size=(64, 2, 2)) * 40.0
    valid = np.stack([s[..., 0], s[..., 1], s[..., 0] ** 2, s[..., 1] ** 2, s[..., 0] * s[..., 1]],
                     -1).mean(axis=1)
    m = np.concatenate([m, big, valid.astype(np.float16).astype(float)])
    _, cov = shading_stats(m, r)
    assert np.all(np.isfinite(cov))
    eig = np.linalg.eigvalsh(cov)
    assert eig.min() >= r * r * (1 - 1e-9)


def test_bad_inputs_raise_prefilter_errors():
    with pytest.raises(PrefilterError, match="normal_map"):
        moments(np.tile([0.0, 0.5, -1.0], (8, 8, 1)))
    with pytest.raises(PrefilterError, match="base_roughness"):
        moments(np.zeros((8, 8)), base_roughness=-1.0)
    with pytest.raises(PrefilterError, match="power-of-two"):
        moments(np.zeros((6, 8)))
    with pytest.raises(PrefilterError, match="texel_size"):
        moments(np.zeros((8, 8)), texel_size=0.0)


def test_bake_command_writes_documented_exr_channels(tmp_path):
    from click.testing import CliRunner

    from prefilter.leadr.commands import bake_leadr
    from prefilter.texture import write_image

    n = 32
    x = np.arange(n)
    h = np.add.outer(np.sin(2 * np.pi * x / n) * 3.0, np.cos(4 * np.pi * x / n) * 2.0)
    write_image(tmp_path / "h.exr", h)
    res = CliRunner().invoke(bake_leadr, [str(tmp_path / "h.exr"), "-o", str(tmp_path / "out"),
                                          "--base-roughness", "0.1"])
    assert res.exit_code == 0, res.output
    info = json.loads((tmp_path / "out" / "leadr.json").read_text())
    assert info["channels"] == ["E_x", "E_y", "E_xx", "E_yy", "E_xy"]
    assert info["base_roughness"] == 0.1 and len(info["levels"]) == 6
    l0 = read_moment_exr(tmp_path / "out" / "leadr_L0.exr")
    # Closed form: h = 3 sin(2 pi i / n) + 2 cos(4 pi j / n), row i = y, column j = x; central
    # differences of a sine of k cycles scale it by sin(2 pi k / n) / (2 pi k / n).
    sx = -2.0 * np.sin(4 * np.pi * x / n) * np.sin(4 * np.pi / n)
    sy = 3.0 * np.cos(2 * np.pi * x / n) * np.sin(2 * np.pi / n)
    np.testing.assert_allclose(l0[..., 0], np.broadcast_to(sx, (n, n)), atol=1e-6)
    np.testing.assert_allclose(l0[..., 1], np.broadcast_to(sy[:, None], (n, n)), atol=1e-6)
    np.testing.assert_allclose(l0[..., 4], np.outer(sy, sx), atol=1e-6)
    top = read_moment_exr(tmp_path / "out" / "leadr_L5.exr")[0, 0]
    np.testing.assert_allclose(top, [0, 0, np.mean(sx**2), np.mean(sy**2), 0], atol=1e-6)
