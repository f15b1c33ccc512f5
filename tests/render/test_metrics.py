"""Metrics against closed forms on tiny images, FLIP sanity, flicker statistics, compare CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from prefilter.errors import PrefilterError
from prefilter.render import metrics as m
from prefilter.texture.io import write_image


def _write_exr(path, rgb):
    write_image(path, np.asarray(rgb, dtype=np.float64))


# ------------------------------------------------------------------------------------ RMSE, relMSE


def test_rmse_constant_offset_is_the_offset():
    b = np.random.default_rng(0).uniform(0, 1, (3, 4, 3))
    assert m.rmse(b + 0.25, b) == pytest.approx(0.25, rel=1e-12)
    assert m.rmse(b - 0.25, b) == pytest.approx(0.25, rel=1e-12)


def test_rmse_single_texel_and_mask():
    b = np.zeros((2, 2, 3))
    a = b.copy()
    a[0, 0, 0] = 3.0  # one of 12 entries differs by 3: MSE = 9/12
    assert m.rmse(a, b) == pytest.approx(math.sqrt(9 / 12))
    mask = np.zeros((2, 2), bool)
    mask[0, 0] = True  # only that pixel: MSE = 9/3
    assert m.rmse(a, b, mask=mask) == pytest.approx(math.sqrt(3.0))
    mask[1, 1] = True  # two pixels, one wrong: 9/6
    assert m.rmse(a, b, mask=mask) == pytest.approx(math.sqrt(1.5))
    weights = np.array([[3.0, 0.0], [0.0, 1.0]])  # weighted: 3*3 / (3*(3+1))
    assert m.rmse(a, b, mask=weights) == pytest.approx(math.sqrt(9 / 4))


def test_rmse_batched_and_broadcast():
    b = np.zeros((2, 2, 3))
    a = np.stack([np.full((2, 2, 3), 0.5), np.full((2, 2, 3), 2.0)])
    np.testing.assert_allclose(m.rmse(a, b), [0.5, 2.0])


def test_relmse_closed_forms():
    b = np.ones((2, 3, 3))
    assert m.relmse(b * 2, b) == pytest.approx(1 / 1.01)
    assert m.relmse(np.full((1, 1, 3), 0.1), np.zeros((1, 1, 3))) == pytest.approx(1.0)
    # per-channel normalisation, channels averaged with equal weight
    ref = np.array([[[0.0, 1.0, 3.0]]])
    expected = (1 / 0.01 + 1 / 1.01 + 1 / 9.01) / 3
    assert m.relmse(ref + 1.0, ref) == pytest.approx(expected)
    assert m.relmse(ref + 1.0, ref, eps=1.0) == pytest.approx((1 / 1 + 1 / 2 + 1 / 10) / 3)


def test_relmse_is_relative_to_the_second_argument():
    a, b = np.full((1, 1, 3), 2.0), np.full((1, 1, 3), 1.0)
    assert m.relmse(a, b, eps=1e-12) == pytest.approx(1.0)
    assert m.relmse(b, a, eps=1e-12) == pytest.approx(0.25)


@pytest.mark.parametrize(
    "a, b, match",
    [
        (np.zeros((2, 2, 3)), np.zeros((2, 3, 3)), "same size"),
        (np.zeros((2, 2, 4)), np.zeros((2, 2, 4)), r"\(\.\.\., 3\)"),
        (np.zeros((2, 3)), np.zeros((2, 3)), "at least 3 dimensions"),
        (np.full((2, 2, 3), np.nan), np.zeros((2, 2, 3)), "finite"),
        (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), "non-empty"),
    ],
)
def test_pair_validation(a, b, match):
    with pytest.raises(PrefilterError, match=match):
        m.rmse(a, b)
    with pytest.raises(PrefilterError, match=match):
        m.relmse(a, b)


def test_mask_and_eps_validation():
    a = np.zeros((2, 2, 3))
    with pytest.raises(PrefilterError, match="selects no pixel"):
        m.rmse(a, a, mask=np.zeros((2, 2), bool))
    with pytest.raises(PrefilterError, match="broadcastable"):
        m.rmse(a, a, mask=np.ones((3, 3), bool))
    with pytest.raises(PrefilterError, match="non-negative"):
        m.rmse(a, a, mask=-np.ones((2, 2)))
    with pytest.raises(PrefilterError, match="eps"):
        m.relmse(a, a, eps=0.0)


# ------------------------------------------------------------------------------------------ FLIP


def _noisy(ref, sigma, seed):
    rng = np.random.default_rng(seed)
    return np.clip(ref + rng.normal(0.0, sigma, ref.shape), 0.0, None)


@pytest.fixture(scope="module")
def flip_reference():
    rng = np.random.default_rng(7)
    # a smooth gradient plus texture, values above 1 so HDR matters
    y, x = np.mgrid[0:48, 0:64] / 64.0
    base = np.stack([x * 2.0, y, 0.5 + 0.5 * np.sin(6 * x)], axis=-1)
    return base + rng.uniform(0, 0.2, base.shape)


def test_flip_identical_is_zero(flip_reference):
    r = m.flip(flip_reference, flip_reference.copy())
    assert r.mean == 0.0
    assert r.error_map.shape == flip_reference.shape[:2]
    assert np.all(r.error_map == 0.0)
    ldr = np.clip(flip_reference / 3.0, 0, 1)
    assert m.flip(ldr, ldr, hdr=False).mean == 0.0


@pytest.mark.parametrize("hdr", [True, False])
def test_flip_grows_with_noise(flip_reference, hdr):
    ref = flip_reference if hdr else np.clip(flip_reference / 3.0, 0, 1)
    means = []
    for sigma in (0.005, 0.03, 0.15):
        test = _noisy(ref, sigma, seed=1)
        if not hdr:
            test = np.clip(test, 0, 1)
        r = m.flip(test, ref, hdr=hdr)
        assert 0.0 <= r.error_map.min() and r.error_map.max() <= 1.0
        assert r.mean == pytest.approx(r.error_map.mean())
        means.append(r.mean)
    assert 0.0 < means[0] < means[1] < means[2] < 1.0


def test_flip_settings_are_reported_and_honoured(flip_reference):
    test = _noisy(flip_reference, 0.05, seed=2)
    auto = m.flip(test, flip_reference)
    s = auto.settings
    assert s["hdr"] and s["tonemapper"] == "aces" and s["num_exposures"] >= 2
    assert s["start_exposure"] <= s["stop_exposure"]
    assert s["ppd"] == pytest.approx(67.0, abs=0.1)  # FLIP's default viewing condition
    fixed = m.flip(test, flip_reference, start_exposure=s["start_exposure"],
                   stop_exposure=s["stop_exposure"], num_exposures=s["num_exposures"])
    assert fixed.mean == pytest.approx(auto.mean, rel=1e-6)
    # a coarser display (fewer pixels per degree) hides less noise: error grows
    assert m.flip(test, flip_reference, ppd=20.0).mean > auto.mean


def test_flip_black_reference_does_not_abort():
    black = np.zeros((8, 8, 3))
    assert m.flip(black, black).mean == 0.0
    lit = np.full((8, 8, 3), 0.5)
    assert m.flip(lit, black).mean > 0.5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"num_exposures": 1}, "num_exposures"),
        ({"start_exposure": 1.0}, "both or neither"),
        ({"start_exposure": 2.0, "stop_exposure": 1.0}, "start_exposure"),
        ({"ppd": 0.0}, "ppd"),
        ({"tonemapper": "filmic"}, "tonemapper"),
    ],
)
def test_flip_rejects_bad_settings(kwargs, match):
    a = np.full((4, 4, 3), 0.5)
    with pytest.raises(PrefilterError, match=match):
        m.flip(a, a, **kwargs)


def test_flip_rejects_bad_images():
    a = np.full((4, 4, 3), 0.5)
    with pytest.raises(PrefilterError, match="non-negative"):
        m.flip(a - 1.0, a)
    with pytest.raises(PrefilterError, match=r"\[0, 1\]"):
        m.flip(a * 3.0, a, hdr=False)
    with pytest.raises(PrefilterError, match="single images"):
        m.flip(np.stack([a, a]), np.stack([a, a]))
    with pytest.raises(PrefilterError, match="same size"):
        m.flip(a, np.full((4, 5, 3), 0.5))


def test_flip_heatmap_uses_magma_endpoints():
    h = m.flip_heatmap(np.array([[0.0, 1.0]]))
    assert h.dtype == np.uint8 and h.shape == (1, 2, 3)
    # magma runs from #000004 to #FCFDBF (matplotlib truncates to bytes: allow 1 step)
    np.testing.assert_allclose(h[0, 0], [0x00, 0x00, 0x04], atol=1)
    np.testing.assert_allclose(h[0, 1], [0xFC, 0xFD, 0xBF], atol=1)
    with pytest.raises(PrefilterError):
        m.flip_heatmap(np.array([[1.5]]))


# --------------------------------------------------------------------------------------- flicker


def test_flicker_constant_frames_is_zero():
    frame = np.random.default_rng(0).uniform(0, 2, (5, 6, 3))
    assert m.flicker(np.stack([frame] * 6)) == 0.0
    assert m.flicker(np.stack([frame] * 6), channels="rgb") == 0.0


def test_flicker_two_levels_closed_form():
    # two grey frames x and y: sample std (ddof=1) of {x, y} is |x - y| / sqrt(2)
    frames = np.stack([np.full((3, 4, 3), 0.2), np.full((3, 4, 3), 0.7)])
    assert m.flicker(frames) == pytest.approx(0.5 / math.sqrt(2))
    # luminance weighting: only the green channel changes
    frames = np.zeros((2, 3, 4, 3))
    frames[1, ..., 1] = 1.0
    assert m.flicker(frames) == pytest.approx(0.7152 / math.sqrt(2))
    assert m.flicker(frames, channels="rgb") == pytest.approx(1 / math.sqrt(2) / 3)


def _c4(k):
    # E[sample std] = c4(k) sigma for k normal samples
    return math.sqrt(2 / (k - 1)) * math.exp(math.lgamma(k / 2) - math.lgamma((k - 1) / 2))


@pytest.mark.parametrize("k", [4, 16])
def test_flicker_of_gaussian_noise_matches_c4_sigma(k):
    sigma, h, w = 0.1, 64, 64
    rng = np.random.default_rng(k)
    grey = rng.normal(0.0, sigma, (k, h, w, 1))
    frames = 0.5 + np.repeat(grey, 3, axis=-1)  # grey noise: luminance noise is sigma
    expected = _c4(k) * sigma
    se = sigma * math.sqrt(1 - _c4(k) ** 2) / math.sqrt(h * w)  # CLT over pixels
    assert abs(m.flicker(frames) - expected) < 5 * se
    # independent channel noise: luminance std is sigma * |w|, per-channel std is sigma
    frames = 0.5 + rng.normal(0.0, sigma, (k, h, w, 3))
    wn = np.linalg.norm(m.LUMINANCE_WEIGHTS)
    assert abs(m.flicker(frames) - expected * wn) < 5 * se * wn
    assert abs(m.flicker(frames, channels="rgb") - expected) < 5 * se


def test_flicker_validation():
    with pytest.raises(PrefilterError, match="K >= 2"):
        m.flicker(np.zeros((1, 2, 2, 3)))
    with pytest.raises(PrefilterError, match="K >= 2"):
        m.flicker(np.zeros((2, 2, 3)))
    with pytest.raises(PrefilterError, match="channels"):
        m.flicker(np.zeros((2, 2, 2, 3)), channels="hsv")


def test_jitter_offsets_are_centred_halton():
    o = m.jitter_offsets(4)
    np.testing.assert_allclose(o + 0.5, [[1 / 2, 1 / 3], [1 / 4, 2 / 3], [3 / 4, 1 / 9],
                                         [1 / 8, 4 / 9]])
    big = m.jitter_offsets(1000)
    assert np.all((big >= -0.5) & (big < 0.5))
    assert abs(big.mean()) < 0.01  # low discrepancy: centred to within ~1/k


def test_flicker_of_a_jittered_render():
    # a render whose brightness follows the x jitter: flicker = sample std of Halton-2 points
    calls = []

    def render(offset):
        calls.append(offset)
        return np.full((2, 3, 3), 1.0 + offset[0])

    xs = np.array([1 / 2, 1 / 4, 3 / 4, 1 / 8])
    expected = math.sqrt(np.sum((xs - xs.mean()) ** 2) / 3)
    assert m.flicker_of(render, k=4) == pytest.approx(expected)
    assert len(calls) == 4


# ------------------------------------------------------------------------------ display encoding


def test_tonemap_and_srgb_known_values():
    # sRGB: linear 0.5 encodes to 0.7354 -> 188; 0.0625 to 1.055 * 0.0625^(1/2.4) - 0.055 -> 71
    assert m.to_srgb8(np.array([0.0, 1.0, 0.5]), method="clamp").tolist() == [0, 255, 188]
    assert m.to_srgb8(np.array([4.0, 0.25, 0.25]), method="clamp", exposure=-2).tolist() == [
        255, 71, 71]
    assert m.linear_to_srgb(0.002) == pytest.approx(12.92 * 0.002)  # linear toe
    # ACES fit at 1: 2.54 / 3.16; Reinhard at 1: 1/2
    assert m.tonemap(np.ones(3))[0] == pytest.approx(2.54 / 3.16)
    assert m.tonemap(np.ones(3), method="reinhard")[0] == pytest.approx(0.5)
    assert m.tonemap(np.full(3, 1e6))[0] == 1.0  # the ACES fit saturates
    assert m.tonemap(np.full(3, -1.0))[0] == 0.0
    lin = np.linspace(0, 1, 101)
    np.testing.assert_allclose(m.srgb_to_linear(m.linear_to_srgb(lin)), lin, atol=1e-12)
    assert m.from_srgb8(np.array([188], np.uint8))[0] == pytest.approx(
        ((188 / 255 + 0.055) / 1.055) ** 2.4)  # = 0.5029: within half a code step of 0.5
    with pytest.raises(PrefilterError, match="method"):
        m.tonemap(np.ones(3), method="filmic")
    with pytest.raises(PrefilterError, match="uint8"):
        m.from_srgb8(np.ones(3))


def test_luminance_weights_sum_to_one():
    assert m.luminance(np.ones(3)) == pytest.approx(1.0)
    assert m.luminance(np.array([0.0, 1.0, 0.0])) == pytest.approx(0.7152)


# ------------------------------------------------------------------------------------ compare CLI


@pytest.fixture()
def exr_pair(tmp_path):
    ref = np.full((6, 8, 3), 0.5)
    test = ref.copy()
    test[0, 0] = [0.5, 0.5, 3.5]  # one entry off by 3 of 144: RMSE = sqrt(9/144) = 0.25
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    _write_exr(a, test)
    _write_exr(b, ref)
    return a, b


def test_compare_cli_prints_and_writes(exr_pair, tmp_path):
    from prefilter.cli import cli

    a, b = exr_pair
    heat, js = tmp_path / "out" / "heat.png", tmp_path / "out" / "m.json"
    res = CliRunner().invoke(cli, ["compare", str(a), str(b), "--heatmap", str(heat),
                                   "--json", str(js)])
    assert res.exit_code == 0, res.output
    assert "RMSE    0.25" in res.output and "HDR-FLIP" in res.output
    data = json.loads(js.read_text())
    assert data["rmse"] == pytest.approx(0.25, rel=1e-6)
    assert data["relmse"] == pytest.approx(9 / (0.25 + 0.01) / 144, rel=1e-6)
    assert 0 < data["flip"] < 1 and data["flip_settings"]["hdr"] is True
    with Image.open(heat) as im:
        assert im.size == (8, 6) and im.mode == "RGB"
        heat_px = np.asarray(im)
    # the heat map is hottest where the images differ
    lum = heat_px.astype(float).sum(-1)
    assert np.unravel_index(np.argmax(lum), lum.shape) == (0, 0)


def test_compare_cli_png_uses_ldr_flip(tmp_path):
    from prefilter.cli import cli

    Image.fromarray(np.full((4, 4, 3), 188, np.uint8)).save(tmp_path / "r.png")
    Image.fromarray(np.full((4, 4, 3), 255, np.uint8)).save(tmp_path / "t.png")
    js = tmp_path / "m.json"
    res = CliRunner().invoke(cli, ["compare", str(tmp_path / "t.png"), str(tmp_path / "r.png"),
                                   "--json", str(js)])
    assert res.exit_code == 0, res.output
    assert "LDR-FLIP" in res.output
    data = json.loads(js.read_text())
    # metrics on linear values: sRGB 188 decodes to ((188/255 + 0.055) / 1.055)^2.4
    ref_lin = ((188 / 255 + 0.055) / 1.055) ** 2.4
    assert data["rmse"] == pytest.approx(1.0 - ref_lin, rel=1e-9)
    assert data["flip_settings"]["hdr"] is False and data["flip"] > 0


def _run_main(argv, capsys):
    from prefilter.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    return exc.value.code, capsys.readouterr().err


def test_compare_cli_shape_mismatch_exits_2(tmp_path, capsys):
    _write_exr(tmp_path / "a.exr", np.zeros((4, 5, 3)))
    _write_exr(tmp_path / "b.exr", np.zeros((4, 6, 3)))
    code, err = _run_main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "b.exr")], capsys)
    assert code == 2
    assert "same size" in err and "5x4" in err and "6x4" in err


def test_compare_cli_unreadable_file_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr")
    _write_exr(tmp_path / "b.exr", np.zeros((4, 5, 3)))
    code, err = _run_main(["compare", str(bad), str(tmp_path / "b.exr")], capsys)
    assert code == 2 and "bad.exr" in err
    code, err = _run_main(["compare", str(tmp_path / "missing.exr"), str(tmp_path / "b.exr")],
                          capsys)
    assert code == 2 and "missing.exr" in err


def test_compare_cli_rejects_mixed_kinds_and_nan(tmp_path, capsys):
    _write_exr(tmp_path / "a.exr", np.zeros((4, 5, 3)))
    Image.fromarray(np.zeros((4, 5, 3), np.uint8)).save(tmp_path / "b.png")
    code, err = _run_main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "b.png")], capsys)
    assert code == 2 and "one of each" in err
    nan = np.zeros((4, 5, 3))
    nan[1, 1, 1] = np.nan
    np.save(tmp_path / "n.npy", nan)
    np.save(tmp_path / "z.npy", np.zeros((4, 5, 3)))
    code, err = _run_main(["compare", str(tmp_path / "n.npy"), str(tmp_path / "z.npy")], capsys)
    assert code == 2 and "n.npy" in err and "finite" in err


def test_compare_grey_exr_counts_as_rgb(tmp_path):
    from prefilter.render.commands import compare_images

    _write_exr(tmp_path / "a.exr", np.full((3, 4, 1), 0.75))
    _write_exr(tmp_path / "b.exr", np.full((3, 4, 3), 0.5))
    res = compare_images(tmp_path / "a.exr", tmp_path / "b.exr")
    assert res["rmse"] == pytest.approx(0.25) and res["relmse"] == pytest.approx(0.0625 / 0.26)
