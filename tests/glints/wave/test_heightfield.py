import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.glints.wave import heightfield as hfm


def test_units_and_texel_size():
    h = np.arange(12.0).reshape(3, 4)
    a = hfm.heightfield(h, 0.5e-6, units="texel")
    assert np.allclose(a.heights, h * 0.5e-6)
    assert hfm.heightfield(h * 1e-6, 0.5e-6).heights.max() == pytest.approx(11e-6)


@pytest.mark.parametrize("heights, texel, match", [
    (np.full((4, 4), np.nan), 1e-6, "heights: expected finite"),
    (np.zeros((4, 4, 3)), 1e-6, r"heights: expected shape \(H, W\)"),
    (np.zeros((0, 4)), 1e-6, "heights: expected at least 2 x 2"),
    (np.zeros((4,)), 1e-6, r"heights: expected shape \(H, W\)"),
    (np.zeros((4, 4)), -1e-6, "texel_size: expected a number > 0"),
    (np.zeros((4, 4)), 0.0, "texel_size: expected a number > 0"),
    ("abc", 1e-6, "heights: expected a numeric"),
])
def test_bad_heightfields_one_clear_error(heights, texel, match):
    with pytest.raises(PrefilterError, match=match):
        hfm.heightfield(heights, texel)


def test_bad_units():
    with pytest.raises(PrefilterError, match="units"):
        hfm.heightfield(np.zeros((4, 4)), 1e-6, units="mm")


def test_upsampled_interpolates_the_samples():
    hf = hfm.isotropic_noise(32, rms=0.1e-6, correlation=3.0)
    for f in (2, 3):
        up = hfm.upsampled(hf, f)
        assert up.shape == (32 * f, 32 * f)
        assert np.allclose(up[::f, ::f], hf.heights, atol=1e-12 * 1e-6)


def test_noise_statistics_and_normals():
    hf = hfm.isotropic_noise(128, rms=0.1e-6, correlation=4.0, texel_size=0.5e-6)
    assert hf.heights.std() == pytest.approx(0.1e-6, rel=1e-9)
    g = hfm.gradient(hf)
    # rms slope per axis sqrt(2) rms / (correlation dx)
    assert g.std() == pytest.approx(np.sqrt(2) * 0.1 / (4 * 0.5), rel=0.15)
    n = hfm.normal_map(hf)
    assert np.allclose(np.linalg.norm(n, axis=-1), 1.0) and n[..., 2].min() > 0


def test_procedural_specs():
    assert hfm.procedural("scratches:32:1").shape == (32, 32)
    assert hfm.procedural("noise:16").shape == (16, 16)
    with pytest.raises(PrefilterError, match="heightfield"):
        hfm.procedural("bumps:16")
