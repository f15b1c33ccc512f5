"""``prefilter bake glints-wave``: the render method's map, resumable, and one clear error for bad
heightfields and options."""

from __future__ import annotations

import json

import numpy as np
import pytest

from prefilter.cli import main
from prefilter.glints.wave import bake as wb
from prefilter.glints.wave import heightfield as hfm

SPEC = "procedural:noise:16:2"


def run_cli(capfd, *args) -> tuple[int, str, str]:
    """``(exit code, stdout, stderr)`` of ``prefilter ARGS`` through the real entry point."""
    capfd.readouterr()
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in args])
    out, err = capfd.readouterr()
    return (0 if exc.value.code is None else exc.value.code), out, err


def one_line_error(rc, err, *words):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith("prefilter: error: "), err
    for w in words:
        assert w in lines[0], (w, err)


def test_bake_to_a_file_writes_the_three_validated_channels(tmp_path, capfd):
    out = tmp_path / "w.npz"
    rc, stdout, err = run_cli(capfd, "bake", "glints-wave", SPEC, "-o", out, "--quiet")
    assert rc == 0, err
    wm = wb.load_wave(out)
    hf = hfm.procedural(SPEC.removeprefix("procedural:"))
    assert hf.digest in wm.level0_key and wm.resolution == wb.WAVE_SETTINGS["ndf_res"]
    summary = json.loads(stdout.strip().splitlines()[-1])
    assert set(summary["channels"]) == {"R", "G", "B"} and 0 < summary["ratio"] < 1
    assert "ratio" in stdout and not (tmp_path / "w.npz.parts").exists()


def test_bake_without_out_is_what_the_render_method_reads(tmp_path, capfd, monkeypatch):
    from prefilter.glints.wave import render as wrender

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "cache"))
    rc, _, err = run_cli(capfd, "bake", "glints-wave", SPEC, "--quiet")
    assert rc == 0, err
    hf = wb.as_heightfield_spec(SPEC)
    path = wb.cache_path(hf, wb.wave_settings(hf.shape))
    assert all(p.exists() for p in wb.channel_paths(path))

    def fail(*args, **kwargs):
        raise AssertionError("the render method baked again")

    monkeypatch.setattr(wrender, "bake_wave", fail)
    monkeypatch.setattr(wrender, "_MAPS", {})
    wm = wrender.wave_map(hf)
    assert wm.channels[0].header == wb.load_wave(path).channels[0].header


def test_cache_path_keys_the_settings_and_the_cp_fit_version(monkeypatch):
    """The render cache's file changes with the settings (``error_weight``) and with the CP
    fit's version: a map fitted by other code is not reused."""
    from prefilter.glints import cp

    hf = wb.as_heightfield_spec(SPEC)
    st = wb.wave_settings(hf.shape)
    path = wb.cache_path(hf, st)
    assert wb.cache_path(hf, dict(st)) == path
    assert wb.cache_path(hf, dict(st, error_weight=0.75)) != path
    monkeypatch.setattr(cp, "FIT_VERSION", cp.FIT_VERSION + 1)
    assert wb.cache_path(hf, st) != path


def test_bake_resumes_from_its_level0_parts(tmp_path, capfd, monkeypatch):
    """A bake stopped after the level-0 images (interrupted as the first channel's CP starts)
    resumes without computing any of them again and writes the bytes of an uninterrupted
    bake."""
    out, ref = tmp_path / "r.npz", tmp_path / "ref.npz"
    assert run_cli(capfd, "bake", "glints-wave", SPEC, "-o", ref, "--quiet")[0] == 0
    real_bake = wb.bake

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(wb, "bake", stop)
    assert run_cli(capfd, "bake", "glints-wave", SPEC, "-o", out, "--quiet")[0] == 130
    assert (tmp_path / "r.npz.parts").is_dir()

    def fail(*args, **kwargs):
        raise AssertionError("level-0 images recomputed")

    monkeypatch.setattr(wb, "bake", real_bake)
    monkeypatch.setattr(wb, "rgb_images", fail)
    rc, _, err = run_cli(capfd, "bake", "glints-wave", SPEC, "-o", out, "--quiet")
    assert rc == 0, err
    for a, b in zip(wb.channel_paths(ref), wb.channel_paths(out)):
        assert a.read_bytes() == b.read_bytes()


def _npy(tmp_path, a, name="h.npy"):
    p = tmp_path / name
    np.save(p, a)
    return p


@pytest.mark.parametrize("case, words", [
    ("nan", ["NaN"]),
    ("3d", ["shape"]),
    ("empty", ["non-empty", "(0, 0)"]),
    ("thin", ["2"]),
])
def test_bad_heightfield_files_give_one_error(tmp_path, capfd, case, words):
    a = {"nan": np.where(np.eye(8) > 0, np.nan, 0.0), "3d": np.zeros((2, 8, 8, 1)),
         "empty": np.zeros((0, 0)), "thin": np.zeros((1, 8))}[case]
    p = _npy(tmp_path, a)
    rc, _, err = run_cli(capfd, "bake", "glints-wave", p, "--texel-size", "2.5e-7", "-o",
                         tmp_path / "o.npz", "--quiet")
    one_line_error(rc, err, *words)
    assert not list(tmp_path.glob("o*"))


@pytest.mark.parametrize("args, words", [
    (["{npy}", "--texel-size", "-1e-7"], ["--texel-size"]),
    (["{npy}", "--texel-size", "0"], ["--texel-size"]),
    (["{npy}", "--texel-size", "nan"], ["--texel-size"]),
    (["{npy}"], ["--texel-size"]),
    (["{tmp}/none.npy", "--texel-size", "1e-7"], ["no such file"]),
    (["procedural:bumps:16"], ["KIND"]),
    (["procedural:noise:x"], ["SIZE"]),
    (["procedural:noise:16", "--units", "texel"], ["--units"]),
    (["procedural:noise:16", "--units", "mm"], ["--units"]),
    (["procedural:noise:16", "--cell", "12"], ["cell"]),
    (["procedural:noise:16", "--stride0", "3"], ["stride0"]),
])
def test_bad_options_give_one_error(tmp_path, capfd, args, words):
    npy = _npy(tmp_path, np.zeros((8, 8)))
    args = [a.format(npy=npy, tmp=tmp_path) for a in args]
    rc, _, err = run_cli(capfd, "bake", "glints-wave", *args, "-o", tmp_path / "o.npz",
                         "--quiet")
    one_line_error(rc, err, *words)
    assert not list(tmp_path.glob("o*"))


def test_a_file_in_texel_units_is_scaled_by_the_texel_size(tmp_path, capfd):
    from prefilter.glints.commands import load_heightfield

    h = np.random.default_rng(0).standard_normal((8, 8))
    p = _npy(tmp_path, h)
    a = load_heightfield(str(p), 2e-7, "texel")
    b = load_heightfield(str(p), 2e-7)
    np.testing.assert_allclose(a.heights, 2e-7 * b.heights)
