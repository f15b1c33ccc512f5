"""The command line on bad input, bad files and unwritable outputs: one line on stderr, no
traceback, exit code 2, and nothing printed before that line (warnings, OpenEXR's messages).

Most cases call :func:`prefilter.cli.main` in this process (``capfd`` sees file descriptors 1
and 2, so native output counts too); a few run ``python -m prefilter`` as a real user would.
Output paths that cannot be written are checked while the command line is parsed, so these
cases fail in well under a second, before any scene, table or map is loaded.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from prefilter.cli import main
from prefilter.texture.io import EXR_CHECKSUM, write_image

SCENE = {
    "camera": {"origin": [0, 1.2, 4], "target": [0, 0, -2], "up": [0, 1, 0], "fov": 40,
               "width": 8, "height": 6},
    "objects": [{"type": "sphere", "center": [0, 0.5, -3], "radius": 0.5,
                 "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04}}],
    "lights": [{"type": "quad", "radiance": [4, 4, 4],
                "vertices": [[-2, 0.5, -8], [2, 0.5, -8], [2, 3, -8], [-2, 3, -8]]}],
}


def run_cli(capfd, *args) -> tuple[int, str, str]:
    """``(exit code, stdout, stderr)`` of ``prefilter ARGS`` run through the real entry point."""
    capfd.readouterr()
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in args])
    out, err = capfd.readouterr()
    code = exc.value.code
    return (0 if code is None else code), out, err


def assert_one_line(rc: int, err: str, *words: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert lines[0].startswith("prefilter: error: "), err
    for w in words:
        assert w in lines[0], (w, err)
    return lines[0]


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "scene.json"
    p.write_text(json.dumps(SCENE))
    return p


@pytest.fixture
def exr(tmp_path):
    p = tmp_path / "a.exr"
    write_image(p, np.random.default_rng(0).random((4, 4, 3)))
    return p


# ------------------------------------------------------------------------------ corrupt files


def _flip(src, dst, offset_from_attr: int, bit: int):
    data = bytearray(src.read_bytes())
    i = data.index(EXR_CHECKSUM.encode())
    data[i + offset_from_attr] ^= 1 << bit
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize("offset", [0, 3, 17, 19, 22],
                         ids=["name-0", "name-3", "type-0", "type-2", "type-5"])
def test_flipped_bit_in_the_exr_checksum_attribute(capfd, exr, tmp_path, offset):
    """A flipped high bit in the checksum attribute's name or type ("string" -> an opaque type
    whose value cannot be formatted) is a one-line error naming the file."""
    bad = _flip(exr, tmp_path / "bad.exr", offset, 7)
    rc, _, err = run_cli(capfd, "compare", bad, exr)
    assert_one_line(rc, err, "bad.exr")


def test_corrupt_exr_prints_no_openexr_messages(capfd, exr, tmp_path):
    """OpenEXR's own messages (on stdout and stderr) go into the error, not before it."""
    data = bytearray(exr.read_bytes())
    i = data.index(EXR_CHECKSUM.encode())
    data[i + 24] ^= 1 << 5  # the attribute's size: the header parse runs into the offsets
    bad = tmp_path / "bad.exr"
    bad.write_bytes(bytes(data))
    rc, out, err = run_cli(capfd, "compare", bad, exr)
    assert_one_line(rc, err, "bad.exr", "corrupt EXR")
    assert out == ""


# --------------------------------------------------------------------------------- scene JSON


@pytest.mark.parametrize("where,digits", [(("camera", "fov"), 401),
                                          (("objects", 0, "radius"), 401),
                                          (("objects", 0, "radius"), 5001)])
def test_json_integer_beyond_the_float_range(capfd, tmp_path, where, digits):
    """A JSON integer such as 10**400 is valid JSON but no float: a one-line error."""
    doc = json.loads(json.dumps(SCENE))
    node = doc
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = "BIG"
    p = tmp_path / "big.json"
    p.write_text(json.dumps(doc).replace('"BIG"', "1" + "0" * (digits - 1)))
    rc, _, err = run_cli(capfd, "render", p, "--out", tmp_path / "o.exr", "--quiet")
    assert_one_line(rc, err, "big.json", "float range")
    assert not (tmp_path / "o.exr").exists()


# ------------------------------------------------------------------------------------- seeds


@pytest.mark.parametrize("args", [
    ["render", "{scene}", "--out", "{tmp}/o.exr", "--seed", "-1"],
    ["bake", "ltc-iso", "--res", "2", "--samples", "2", "-o", "{tmp}/t.npz", "--seed", "-1"],
    ["bake", "ltc-aniso", "--res", "2", "-o", "{tmp}/t.npz", "--seed", "-1"],
    ["bake", "glints", "procedural:gaussian:32", "-o", "{tmp}/g.npz", "--seed", "-1"],
    ["bake", "glints-wang", "procedural:gaussian:32", "-o", "{tmp}/g.npz", "--seed", "-1"],
    ["bake", "glints", "procedural:gaussian:32:-1", "-o", "{tmp}/g.npz"],
    ["bake", "glints-wang", "procedural:gaussian:32:-1", "-o", "{tmp}/g.npz"],
    ["validate", "--seed", "-1"],
    ["multiscale-fit", "--seed", "-1"],
    ["demo", "--out", "{tmp}/demo", "--seed", "-1"],
    ["render", "{scene}", "--out", "{tmp}/o.exr", "--seed", str(2**63)],
], ids=lambda a: " ".join(a[:2]) + (" spec" if a[-1].endswith(":-1") else ""))
def test_negative_seeds_are_refused(capfd, scene, tmp_path, args):
    args = [a.format(scene=scene, tmp=tmp_path) for a in args]
    rc, _, err = run_cli(capfd, *args)
    line = assert_one_line(rc, err)
    assert "seed" in line.lower(), line
    assert not any(tmp_path.glob("*.npz")) and not (tmp_path / "o.exr").exists()


# -------------------------------------------------------------------------- unwritable outputs


@pytest.mark.parametrize("args,path", [
    (["render", "{scene}", "--out", "/dev/null/x.exr"], "/dev/null/x.exr"),
    (["render", "{scene}", "--out", "{tmp}/o.exr", "--png", "/proc/x.png"], "/proc/x.png"),
    (["render", "{scene}", "--out", "{tmp}/file.txt/o.exr"], "file.txt/o.exr"),
    (["compare", "{exr}", "{exr}", "--heatmap", "/dev/null/x.png"], "/dev/null/x.png"),
    (["compare", "{exr}", "{exr}", "--json", "/proc/m.json"], "/proc/m.json"),
    (["export", "{scene}", "--out", "/proc/x"], "/proc/x"),
    (["export", "--out", "{tmp}/file.txt"], "file.txt"),
    (["bake", "colormap", "{exr}", "--sigma-max", "0.1", "-o", "{tmp}/c.exr", "--glsl",
      "/proc/x.glsl"], "/proc/x.glsl"),
    (["bake", "colormap", "{exr}", "--sigma-max", "0.1", "-o", "/dev/null/c.exr"],
     "/dev/null/c.exr"),
    (["bake", "leadr", "{exr}", "-o", "/proc/x"], "/proc/x"),
    (["bake", "ltc-iso", "--res", "2", "--samples", "2", "-o", "/proc/x.npz"], "/proc/x.npz"),
    (["bake", "ltc-aniso", "--res", "2", "-o", "/proc/x.npz"], "/proc/x.npz"),
    (["bake", "glints", "procedural:gaussian:32", "-o", "/proc/g.npz"], "/proc/g.npz"),
    (["bake", "glints-wang", "procedural:gaussian:32", "-o", "/proc/g.npz"], "/proc/g.npz"),
    (["validate", "--configs", "1", "--json", "/proc/v.json"], "/proc/v.json"),
    (["multiscale-fit", "--out", "/proc/f.json"], "/proc/f.json"),
    (["demo", "--out", "/proc/demo"], "/proc/demo"),
], ids=lambda a: " ".join(a[:2]) if isinstance(a, list) else None)
def test_unwritable_outputs_fail_before_the_work(capfd, scene, exr, tmp_path, args, path):
    (tmp_path / "file.txt").write_text("not a folder")
    args = [a.format(scene=scene, exr=exr, tmp=tmp_path) for a in args]
    rc, out, err = run_cli(capfd, *args)
    line = assert_one_line(rc, err, path)
    assert "cannot write" in line or "is a file" in line, line
    assert out == ""  # no work was done (no progress, no result line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "file.txt", "scene.json"]


def test_writable_outputs_in_new_folders_still_work(capfd, scene, tmp_path):
    """Missing parent folders are created by the writers: the check accepts them."""
    rc, out, err = run_cli(capfd, "render", scene, "--out", tmp_path / "new/dir/o.exr",
                           "--quiet")
    assert rc == 0, err
    assert (tmp_path / "new/dir/o.exr").is_file()


# ------------------------------------------------------------------------------ usage errors


@pytest.mark.parametrize("args,words", [
    (["render"], ["Missing argument 'SCENE'", "prefilter render --help"]),
    (["render", "{scene}", "--bogus"], ["--bogus", "prefilter render --help"]),
    (["rendr"], ["No such command 'rendr'"]),
    (["bake", "ltc-iso", "--res", "1"], ["--res"]),
    (["render", "{scene}", "--out", "{tmp}/o.exr", "--spp", "x"], ["--spp"]),
    (["render", "{tmp}/missing.json", "--out", "{tmp}/o.exr"], ["missing.json"]),
])
def test_usage_errors_are_one_line(capfd, scene, tmp_path, args, words):
    args = [a.format(scene=scene, tmp=tmp_path) for a in args]
    rc, _, err = run_cli(capfd, *args)
    assert_one_line(rc, err, *words)


# --------------------------------------------------------------------- as a separate process


def _subprocess(*args):
    return subprocess.run([sys.executable, "-m", "prefilter", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_process_corrupt_exr(exr, tmp_path):
    bad = _flip(exr, tmp_path / "bad.exr", 17, 7)
    r = _subprocess("compare", bad, exr)
    assert_one_line(r.returncode, r.stderr, "bad.exr", EXR_CHECKSUM)
    assert r.stdout == ""


def test_process_unwritable_output_and_usage(scene):
    r = _subprocess("render", scene, "--out", "/dev/null/x.exr")
    assert_one_line(r.returncode, r.stderr, "/dev/null/x.exr")
    r = _subprocess("render", scene, "--bogus")
    assert_one_line(r.returncode, r.stderr, "--bogus")


def test_process_negative_seed_in_procedural_spec(tmp_path):
    r = _subprocess("bake", "glints", "procedural:gaussian:32:-1", "-o", tmp_path / "g.npz")
    assert_one_line(r.returncode, r.stderr, "procedural:gaussian:32:-1")
