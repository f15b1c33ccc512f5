"""File fuzzing (issue 10): every format the package reads, corrupted in several ways.

Each corruption must end in a :class:`~prefilter.errors.PrefilterError` whose message names the
file, never another exception; a corruption the reader does not notice must give exactly the
original result (compared array by array), so a silently different table is a failure. Formats
written by the package carry checksums (``__meta__`` in ``.npz``, ``prefilter_sha256`` in EXR,
``sha256`` / ``meta_sha256`` in JSON sidecars, PNG chunk CRCs), so a flipped bit in their data
is caught. Hand-written scenes have no checksum: a flipped bit may turn into another valid scene,
which is accepted (counted, not failed), but must never raise anything but a named error.

Formats x kinds run here: see ``CASES`` (the test ids); the corruption kinds are ``truncate``
(several offsets), ``bitflip`` (seeded random offsets), ``magic`` (wrong header bytes), ``dtype``,
``shape``, ``missing`` (key / field / array), ``unknown`` (extra key) and ``version``.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from prefilter.fileio import META_KEY, save_npz_atomic
from prefilter.errors import PrefilterError, TableFileError

N_FLIPS = 48
TRUNCATE_FRACTIONS = (0.0, 0.001, 0.1, 0.25, 0.5, 0.75, 0.9, 0.999)


# -- valid small files ---------------------------------------------------------------------------


def _make_iso(d: Path) -> Path:
    from prefilter.ltc.table import GGXTable

    t = GGXTable.load()
    i = np.array([0, 21, 42, len(t.axis_t) - 1])
    j = np.array([0, 21, 42, len(t.axis_r) - 1])
    p = d / "iso.npz"
    save_npz_atomic(p, version=np.int64(1), axis_t=t.axis_t[i], axis_r=t.axis_r[j],
                    M=t.M[np.ix_(i, j)], magnitude=t.magnitude[np.ix_(i, j)],
                    fresnel=t.fresnel[np.ix_(i, j)], fit_error=t.fit_error[np.ix_(i, j)],
                    settings=np.array(json.dumps(t.settings, sort_keys=True)))
    return p


def _load_iso(p: Path) -> dict:
    from prefilter.ltc.table import GGXTable

    t = GGXTable.load(p)
    return {"t": t.axis_t, "r": t.axis_r, "M": t.M, "n": t.magnitude, "f": t.fresnel,
            "e": t.fit_error, "s": np.array(json.dumps(t.settings, sort_keys=True))}


def _make_aniso(d: Path) -> Path:
    from prefilter.ltc.aniso.table import AnisoGGXTable

    t = AnisoGGXTable.load()
    k = np.array([0, 3, 7])
    ix = np.ix_(k, k, k, k)
    small = AnisoGGXTable([a[k] for a in t.axes], t.M[ix], t.magnitude[ix], t.fresnel[ix],
                          t.settings, {"l1": t.diagnostics["l1"][ix]})
    p = d / "aniso.npz"
    small.save(p)
    return p


def _load_aniso(p: Path) -> dict:
    from prefilter.ltc.aniso.table import AnisoGGXTable

    t = AnisoGGXTable.load(p)
    out = {f"axis{i}": a for i, a in enumerate(t.axes)}
    out.update(M=t.M, n=t.magnitude, f=t.fresnel, s=np.array(json.dumps(t.settings)),
               **{f"d_{k}": v for k, v in t.diagnostics.items()})
    return out


def _make_glints(d: Path) -> Path:
    from prefilter.glints.bake import bake
    from prefilter.texture.procedural import normal_map

    p = d / "glints.npz"
    bake(normal_map("gaussian", 32, 1), p, rank=2, ndf_res=8, block=4, cell=16, n_iter_max=10,
         progress=False)
    return p


def _load_glints(p: Path) -> dict:
    from prefilter.glints.store import ARRAYS, load

    gm = load(p)
    return {"h": np.array(json.dumps(gm.header, sort_keys=True)),
            **{k: getattr(gm, k) for k in ARRAYS}}


def _colormap_table():
    from prefilter.colormap.table import prefilter_table

    x = np.linspace(0.0, 1.0, 8)
    return prefilter_table(np.stack([x, x**2, 1 - x], -1), (0.0, 2.0), 0.3, size=8, n_sigma=4)


def _make_colormap(suffix: str, corrupt: str):
    def make(d: Path) -> Path:
        img, side = _colormap_table().save(d / f"cmap{suffix}", meta={"source": "test"})
        return side if corrupt == "json" else img

    return make


def _load_colormap(suffix: str):
    def load(p: Path) -> dict:
        from prefilter.colormap.table import ColormapTable

        t = ColormapTable.load(p.with_suffix(suffix))
        return {"T": t.table, "v": np.array(t.value_range), "s": np.array(t.sigma_max),
                "e": np.array(t.edge)}

    return load


def _make_leadr(corrupt: str):
    def make(d: Path) -> Path:
        from prefilter.leadr.io import write_maps
        from prefilter.leadr.maps import moments

        rng = np.random.default_rng(3)
        write_maps(moments(rng.normal(size=(8, 8)), 1.0, 0.05), d / "leadr",
                   meta={"source": "test"})
        return d / "leadr" / corrupt

    return make


def _load_leadr(p: Path) -> dict:
    from prefilter.leadr.io import read_maps

    levels, info = read_maps(p.parent)
    return {**{f"L{i}": lv for i, lv in enumerate(levels)},
            "b": np.array(info["base_roughness"])}


def _make_image(name: str, shape, **kw):
    def make(d: Path) -> Path:
        from prefilter.texture.io import write_image

        rng = np.random.default_rng(5)
        return write_image(d / name, rng.random(shape), **kw)

    return make


def _load_image(p: Path) -> dict:
    from prefilter.texture.io import read_image

    return {"img": read_image(p)}


def _make_normals_npy(d: Path) -> Path:
    from prefilter.texture.procedural import normal_map

    p = d / "normals.npy"
    np.save(p, normal_map("gaussian", 8, 1))
    return p


def _load_normals_npy(p: Path) -> None:
    from prefilter.glints.commands import load_normal_map

    load_normal_map(str(p))
    return None  # user data without a checksum: any valid parse is accepted


SCENE = {
    "camera": {"origin": [0, 1, 3], "target": [0, 0, 0], "fov": 40, "width": 8, "height": 6},
    "objects": [{"type": "plane", "size": [4, 4],
                 "material": {"alpha": 0.3, "base_color": [0.5, 0.5, 0.5]}},
                {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                 "material": {"alpha_x": 0.2, "alpha_y": 0.4}}],
    "lights": [{"type": "quad", "vertices": [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]],
                "radiance": [4, 4, 4]},
               {"type": "point", "position": [1, 3, 1], "intensity": 2.0}],
}

SCENE_TOML = """\
[camera]
origin = [0, 1, 3]
target = [0, 0, 0]
fov = 40
width = 8
height = 6

[[objects]]
type = "plane"
size = [4, 4]
material = { alpha = 0.3, base_color = [0.5, 0.5, 0.5] }

[[lights]]
type = "point"
position = [1, 3, 1]
intensity = 2.0
"""


def _make_scene(d: Path) -> Path:
    p = d / "scene.json"
    p.write_text(json.dumps(SCENE, indent=1))
    return p


def _make_scene_toml(d: Path) -> Path:
    p = d / "scene.toml"
    p.write_text(SCENE_TOML)
    return p


def _load_scene(p: Path) -> None:
    from prefilter.render.scene import load_scene

    load_scene(p)
    return None  # hand-written scenes carry no checksum: any valid parse is accepted


# -- structural corruptions ------------------------------------------------------------------------


def _rewrite_npz(fn: Callable[[dict], None], *, version: int | None = None):
    """Rewrite an .npz with ``fn`` applied to its arrays and a FRESH valid checksum, so that
    only the reader's layout checks can catch the change."""

    def corrupt(p: Path) -> None:
        with np.load(p, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files if k != META_KEY}
            meta = json.loads(str(z[META_KEY]))
        fn(a)
        save_npz_atomic(p, format_name=meta.get("format"),
                        format_version=version if version is not None else meta.get("version"),
                        **a)

    return corrupt


def _set(key, value_fn):
    def fn(a):
        a[key] = value_fn(a[key])

    return fn


def _drop(key):
    def fn(a):
        del a[key]

    return fn


def _glints_header(**changes):
    def fn(a):
        h = json.loads(str(a["header"]))
        h.update(changes)
        a["header"] = np.array(json.dumps(h, sort_keys=True))

    return fn


def _edit_json(fn: Callable[[dict], None], *, resign: bool = True):
    """Edit a JSON sidecar; ``resign`` recomputes its ``meta_sha256`` so only the field checks
    can catch the change."""

    def corrupt(p: Path) -> None:
        from prefilter.fileio import json_digest

        info = json.loads(p.read_text())
        old = info.pop("meta_sha256", None)
        fn(info)
        info["meta_sha256"] = json_digest(info) if resign else old
        p.write_text(json.dumps(info))

    return corrupt


def _json_set(key, value):
    def fn(info):
        info[key] = value

    return fn


def _json_del(key):
    def fn(info):
        del info[key]

    return fn


def _rewrite_image(shape=None, **kw):
    """Overwrite a table image with another one of the same name (other shape or encoding)."""

    def corrupt(p: Path) -> None:
        from prefilter.texture.io import read_image, write_image

        a = read_image(p)
        if shape is not None:
            a = np.resize(a, shape(a.shape))
        write_image(p, a, **kw)

    return corrupt


def _exr_as_half(p: Path) -> None:
    """Rewrite an EXR's channels as float16 (a valid EXR with its own valid checksum)."""
    from prefilter.texture.io import read_exr_channels, write_exr_channels

    write_exr_channels(p, {k: v.astype(np.float16) for k, v in read_exr_channels(p).items()})


def _scene_edit(fn: Callable[[dict], None]):
    def corrupt(p: Path) -> None:
        data = json.loads(p.read_text())
        fn(data)
        p.write_text(json.dumps(data))

    return corrupt


def _npz_bytes(p: Path) -> bytes:
    q = p.with_name("x.npz")
    np.savez(q, a=np.zeros(3))
    return q.read_bytes()


def _magic(p: Path) -> None:
    data = bytearray(p.read_bytes())
    data[:4] = b"\x00JNK"
    p.write_bytes(bytes(data))


def _other_format(src_suffix: str):
    """Put a file of another format under this name (e.g. an EXR named .png)."""

    def corrupt(p: Path) -> None:
        from prefilter.texture.io import write_image

        q = write_image(p.with_name("other" + src_suffix), np.full((4, 4, 3), 0.5))
        p.write_bytes(q.read_bytes())

    return corrupt


# -- the formats -----------------------------------------------------------------------------------


@dataclass
class Fmt:
    make: Callable[[Path], Path]
    load: Callable[[Path], dict | None]
    structural: dict[str, Callable[[Path], None]]


FORMATS = {
    "iso_table": Fmt(_make_iso, _load_iso, {
        "dtype": _rewrite_npz(_set("M", lambda m: m.astype(np.int64))),
        "dtype_text": _rewrite_npz(_set("magnitude", lambda m: m.astype(str))),
        "shape": _rewrite_npz(_set("M", lambda m: m.reshape(m.shape[:2] + (9,)))),
        "layout": _rewrite_npz(_set("axis_t", lambda t: t[::-1].copy())),
        "missing": _rewrite_npz(_drop("fresnel")),
        "version": _rewrite_npz(_set("version", lambda v: np.int64(2)), version=2),
    }),
    "aniso_table": Fmt(_make_aniso, _load_aniso, {
        "dtype": _rewrite_npz(_set("fresnel", lambda m: m.astype(np.complex128))),
        "dtype_text": _rewrite_npz(_set("settings", lambda s: np.float64(1.0))),
        "shape": _rewrite_npz(_set("magnitude", lambda m: m[:, :, :, :1])),
        "missing": _rewrite_npz(_drop("axis_phi")),
        "unknown": _rewrite_npz(lambda a: a.update(extra=np.zeros(3))),
        "version": _rewrite_npz(_set("version", lambda v: np.int64(2)), version=2),
    }),
    "glints_map": Fmt(_make_glints, _load_glints, {
        "dtype": _rewrite_npz(_set("block_mask", lambda b: b.astype(np.int64))),
        "dtype_text": _rewrite_npz(_set("header", lambda h: np.array([1, 2]))),
        "shape": _rewrite_npz(_set("c", lambda c: c[..., :-1].copy())),
        "layout": _rewrite_npz(_set("block_mask", lambda b: np.zeros_like(b))),
        "missing": _rewrite_npz(_drop("a")),
        "missing_field": _rewrite_npz(lambda a: _glints_header(ndf=None)(a)),
        "version": _rewrite_npz(_glints_header(version=99), version=99),
    }),
    "colormap_png": Fmt(_make_colormap(".png", "img"), _load_colormap(".png"), {
        "dtype": _rewrite_image(bits=8),
        "shape": _rewrite_image(shape=lambda s: (s[0] + 1,) + s[1:], bits=16),
        "wrong_format": _other_format(".exr"),
    }),
    "colormap_exr": Fmt(_make_colormap(".exr", "img"), _load_colormap(".exr"), {
        "dtype": _rewrite_image(half=True),
        "shape": _rewrite_image(shape=lambda s: s[:2] + (1,)),
        "wrong_format": _other_format(".png"),
    }),
    "colormap_json": Fmt(_make_colormap(".png", "json"), _load_colormap(".png"), {
        "dtype": _edit_json(_json_set("n_mean", "8")),
        "shape": _edit_json(_json_set("n_mean", 9)),
        "missing": _edit_json(_json_del("edge")),
        "version": _edit_json(_json_set("version", 2)),
        "unsigned_edit": _edit_json(_json_set("sigma_max", 0.4), resign=False),
        "not_object": lambda p: p.write_text("[1, 2]"),
    }),
    "leadr_exr": Fmt(_make_leadr("leadr_L0.exr"), _load_leadr, {
        "dtype": _exr_as_half,
        "wrong_format": _other_format(".png"),
    }),
    "leadr_json": Fmt(_make_leadr("leadr.json"), _load_leadr, {
        "dtype": _edit_json(_json_set("base_roughness", "0.05")),
        "shape": _edit_json(lambda i: i["levels"][0].update(shape=[4, 8])),
        "missing": _edit_json(_json_del("levels")),
        "missing_file": _edit_json(lambda i: i["levels"][1].update(file="nope.exr")),
        "version": _edit_json(_json_set("version", 2)),
        "unsigned_edit": _edit_json(_json_set("base_roughness", 0.5), resign=False),
    }),
    "png8": Fmt(_make_image("i8.png", (6, 5, 3)), _load_image, {
        "wrong_format": _other_format(".exr")}),
    "png16_rgb": Fmt(_make_image("i16.png", (6, 5, 3), bits=16), _load_image, {
        "wrong_format": _other_format(".exr")}),
    "png16_gray": Fmt(_make_image("g16.png", (6, 5), bits=16), _load_image, {}),
    "exr": Fmt(_make_image("i.exr", (6, 5, 4)), _load_image, {
        "wrong_format": _other_format(".png")}),
    "exr_half": Fmt(_make_image("h.exr", (6, 5, 1), half=True), _load_image, {}),
    "normals_npy": Fmt(_make_normals_npy, _load_normals_npy, {
        "dtype": lambda p: np.save(p, np.array(["a", "b"])),
        "shape": lambda p: np.save(p, np.zeros((4, 4, 2))),
        "npz": lambda p: p.write_bytes(_npz_bytes(p)),
    }),
    "scene_json": Fmt(_make_scene, _load_scene, {
        "dtype": _scene_edit(lambda s: s["camera"].update(fov="40")),
        "shape": _scene_edit(lambda s: s["camera"].update(origin=[0, 1])),
        "missing": _scene_edit(lambda s: s.pop("camera")),
        "missing_nested": _scene_edit(lambda s: s["lights"][0].pop("radiance")),
        "unknown": _scene_edit(lambda s: s.update(version=1)),
        "unknown_nested": _scene_edit(lambda s: s["objects"][0]["material"].update(rough=1)),
        "not_object": lambda p: p.write_text("[1, 2]"),
        "not_utf8": lambda p: p.write_bytes(b'{"camera": "\xff\xfe"}'),
        "deep": lambda p: p.write_text("[" * 100_000 + "]" * 100_000),
    }),
    "scene_toml": Fmt(_make_scene_toml, _load_scene, {
        "dtype": lambda p: p.write_text(SCENE_TOML.replace("fov = 40", 'fov = "40"')),
        "missing": lambda p: p.write_text(SCENE_TOML.replace("width = 8\n", "")),
        "unknown": lambda p: p.write_text(SCENE_TOML.replace("fov = 40", "fov = 40\nzoom = 2")),
    }),
}

GENERIC = ("truncate", "bitflip", "magic")
CASES = [(f, k) for f in FORMATS for k in GENERIC + tuple(FORMATS[f].structural)]


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    """Valid files of every format, made once; each test corrupts a fresh copy."""
    root = tmp_path_factory.mktemp("fuzz_originals")
    out = {}
    for name, fmt in FORMATS.items():
        d = root / name
        d.mkdir()
        p = fmt.make(d)
        out[name] = (d, p, fmt.load(p))  # the valid file loads
    return out


def _fresh_copy(src_dir: Path, dst_dir: Path, target: Path) -> Path:
    import shutil

    shutil.copytree(src_dir, dst_dir)
    return dst_dir / target.relative_to(src_dir)


def _same(a: dict | None, b: dict | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.keys() == b.keys() and all(
        a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and np.array_equal(a[k], b[k])
        for k in a)


def _outcome(fmt: Fmt, p: Path, expected) -> str:
    """"error" (a PrefilterError naming the file), "same" (loaded, identical result), or an
    assertion failure for anything else."""
    try:
        got = fmt.load(p)
    except PrefilterError as exc:
        msg = str(exc)
        assert p.name in msg or p.parent.name in msg, f"error does not name {p}: {msg}"
        return "error"
    if expected is None:  # scenes, user .npy: no checksum, another valid file is acceptable
        return "parsed"
    assert _same(got, expected), f"{p}: corrupted file loaded with a different result"
    return "same"


@pytest.mark.parametrize("fmt_name,kind", CASES, ids=[f"{f}-{k}" for f, k in CASES])
def test_corrupted_file(fmt_name, kind, originals, tmp_path):
    fmt = FORMATS[fmt_name]
    src_dir, src, expected = originals[fmt_name]
    if kind in ("truncate", "bitflip"):
        outcomes = _generic(fmt_name, kind, fmt, src_dir, src, expected, tmp_path, N_FLIPS)
        if kind == "bitflip" and expected is not None:
            # checksummed formats: flips in array data are caught, never loaded differently
            assert outcomes.count("error") >= N_FLIPS // 2, outcomes
    else:
        p = _fresh_copy(src_dir, tmp_path / "c", src)
        (_magic if kind == "magic" else fmt.structural[kind])(p)
        assert _outcome(fmt, p, expected) == "error"


@pytest.mark.slow
@pytest.mark.parametrize("fmt_name", list(FORMATS))
def test_many_bit_flips(fmt_name, originals, tmp_path):
    """400 seeded flips per format: each is a named error or loads the identical result."""
    fmt = FORMATS[fmt_name]
    src_dir, src, expected = originals[fmt_name]
    _generic(fmt_name + "-many", "bitflip", fmt, src_dir, src, expected, tmp_path, 400)


def _generic(seed_name, kind, fmt, src_dir, src, expected, tmp_path, n_flips):
    data = src.read_bytes()
    outcomes = []
    if kind == "truncate":
        cuts = sorted({int(f * len(data)) for f in TRUNCATE_FRACTIONS} | {len(data) - 1})
        for i, n in enumerate(cuts):
            p = _fresh_copy(src_dir, tmp_path / f"t{i}", src)
            p.write_bytes(data[:n])
            outcome = _outcome(fmt, p, expected)
            # a truncated file is never accepted, even when its prefix happens to parse (text
            # formats may lose trailing whitespace only)
            assert outcome == "error" or not data[n:].strip(), (n, outcome)
    elif kind == "bitflip":
        rng = np.random.default_rng(zlib.crc32(seed_name.encode()))
        for i in range(n_flips):
            p = _fresh_copy(src_dir, tmp_path / f"f{i}", src)
            b = bytearray(data)
            pos = int(rng.integers(len(b)))
            b[pos] ^= 1 << int(rng.integers(8))
            p.write_bytes(bytes(b))
            outcomes.append(_outcome(fmt, p, expected))
    return outcomes


def test_checksum_catches_a_flip_in_array_data(originals, tmp_path):
    """A bit flipped inside the bytes of an array (not the zip structure) of a table file is
    reported as a checksum mismatch, not loaded."""
    from prefilter.ltc.table import GGXTable

    src_dir, src, _ = originals["iso_table"]
    data = bytearray(src.read_bytes())
    with np.load(src) as z:
        m = z["M"]
    needle = m.tobytes()[:16]
    pos = bytes(data).find(needle)
    assert pos > 0
    data[pos + 3] ^= 0x10
    p = tmp_path / "iso.npz"
    p.write_bytes(bytes(data))
    with pytest.raises(PrefilterError, match=r"iso\.npz.*(sha256|CRC|unreadable)"):
        GGXTable.load(p)


def test_files_without_checksum_are_refused(originals, tmp_path):
    """Removing the ``__meta__`` entry does not turn the checksum off: an otherwise valid table
    without it (here with an edited entry) is refused, naming the file and the entry."""
    from prefilter.ltc.table import GGXTable

    _, src, _ = originals["iso_table"]
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files if k != META_KEY}
    arrays["magnitude"] = arrays["magnitude"] * 0.5
    p = tmp_path / "edited.npz"
    np.savez(p, **arrays)
    with pytest.raises(TableFileError, match=r"edited\.npz: __meta__: expected the checksum"):
        GGXTable.load(p)


def test_cli_reports_a_corrupt_table_in_one_line(originals, tmp_path):
    """``prefilter render --table BAD`` exits with code 2 and a one-line error naming the file."""
    import subprocess
    import sys

    _, src, _ = originals["iso_table"]
    bad = tmp_path / "bad.npz"
    bad.write_bytes(src.read_bytes()[:100])
    scene = _make_scene(tmp_path)
    r = subprocess.run([sys.executable, "-m", "prefilter.cli", "render", str(scene), "--out",
                        str(tmp_path / "o.exr"), "--table", str(bad), "--quiet"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "bad.npz" in lines[0] and "Traceback" not in r.stderr


def test_toml_scene_is_the_same_scene_as_json(tmp_path):
    """The TOML reader gives the scene the equivalent JSON document describes."""
    from prefilter.render.scene import load_scene

    toml = load_scene(_make_scene_toml(tmp_path))
    as_json = {"camera": SCENE["camera"], "objects": [dict(SCENE["objects"][0])],
               "lights": [SCENE["lights"][1]]}
    ref = load_scene(as_json)
    assert toml.to_dict() == ref.to_dict()
    a, b = toml.objects[0], ref.objects[0]
    assert a.material.alpha_x == b.material.alpha_x == 0.3
    np.testing.assert_array_equal(a.material.base_color, b.material.base_color)
    np.testing.assert_array_equal(a.size, [4.0, 4.0])
    np.testing.assert_array_equal(toml.lights[0].intensity, [2.0, 2.0, 2.0])
