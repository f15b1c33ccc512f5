"""On-disk format of per-tile Wang pyramids (``wang_store``): round trips (every query equal after
load of a version-1 file, compressed and not; version 2's codes within half a step), deterministic
bytes, corrupt / truncated / wrong-version / inconsistent files (each a TableFileError naming the
file and the field), and the ``prefilter bake glints-wang`` CLI."""

import json
from dataclasses import replace

import numpy as np
import pytest
from maps import sinusoid

from prefilter.fileio import META_KEY, save_npz_atomic
from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.wang import index_map, synthesize
from prefilter.glints.wang_ndf import (bake_tiles, compress_tiles, ndf, ndf_image, ndf_points,
                                       sample)
from prefilter.glints.store import CODE_DTYPES
from prefilter.glints.wang_store import (FORMAT, VERSION, encode_level, load_tiles,
                                         save_tiles)

T, R = 8, 16


@pytest.fixture(scope="module")
def wn():
    wt = synthesize(sinusoid(32, ax=0.25, ay=0.2, px=16, py=8), tile=T, band=2.0, rng=3)
    return bake_tiles(wt, ndf_res=R, support=0.5, intrinsic_roughness=0.01)


@pytest.fixture(scope="module")
def wc(wn):
    return compress_tiles(wn, 2, 8, n_iter_max=5)


@pytest.fixture(scope="module")
def saved(wn, tmp_path_factory):
    path = tmp_path_factory.mktemp("wang") / "tiles.npz"
    save_tiles(wn, path)
    return path


# one footprint per regime: direct, per-tile (levels 0 and 1), tile-type shares, expected tiling
FOOTPRINTS = [((3.3, 5.1), 0.8), ((8.2, 15.9), 1.7), ((-20.4, 33.3), 3.1), ((5.0, 7.0), 6.0),
              ((1e4 + 0.3, -77.7), 100.0)]


def _same_queries(a, b):
    g = np.linspace(-0.5, 0.5, R, endpoint=False) + 0.5 / R
    s = np.stack(np.meshgrid(g, g), -1)
    idx = index_map(a.wang, 6, 6, -3, -1)
    for c, sp in FOOTPRINTS:
        for index in (None, idx):
            np.testing.assert_array_equal(ndf_image(a, c, sp, index=index),
                                          ndf_image(b, c, sp, index=index))
        np.testing.assert_array_equal(ndf(a, c, sp, s), ndf(b, c, sp, s))
        sa, pa = sample(a, c, sp, 200, rng=5)
        sb, pb = sample(b, c, sp, 200, rng=5)
        np.testing.assert_array_equal(sa, sb)
        np.testing.assert_array_equal(pa, pb)


def test_round_trip_uncompressed(wn, saved):
    back = load_tiles(saved)
    assert back.nbytes == wn.nbytes and back.n_levels == wn.n_levels >= 2
    assert back.wang.seed == wn.wang.seed and back.k0 == wn.k0 and back.block == 0
    assert (back.uniform_sigma, back.wide_sigma, back.sigma0) == (wn.uniform_sigma,
                                                                   wn.wide_sigma, wn.sigma0)
    _same_queries(wn, back)
    rng = np.random.default_rng(1)
    c = rng.uniform(-40, 40, (30, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(80.0), 30))
    s = rng.uniform(-0.5, 0.5, (30, 2))
    got = ndf_points(back, c, sp, s)
    np.testing.assert_array_equal(got, ndf_points(wn, c, sp, s))
    assert got.max() > 1.0


def test_round_trip_compressed_float32(wc, tmp_path):
    """code_bits=0: the version-1 layout (float32 factors), every query bitwise equal."""
    save_tiles(wc, tmp_path / "c.npz", code_bits=0)
    back = load_tiles(tmp_path / "c.npz")
    assert back.block == 8 and back.cp_error == wc.cp_error and back.nbytes == wc.nbytes
    _same_queries(wc, back)
    header = json.loads(str(np.load(tmp_path / "c.npz")["header"]))
    assert header["format"] == FORMAT and header["version"] == 1
    assert header["settings"]["rank"] == 2 and header["tile"] == T
    assert header["arrays"]["C_0"]["shape"] == list(wc.images[0][2].shape)
    assert "code_bits" not in header["settings"]


@pytest.mark.parametrize("bits", [8, 16])
def test_round_trip_codes(wc, tmp_path, bits):
    """Version 2: each decoded factor within half a code step of the original, relative to its
    component's scale (``A``, ``Bf`` normalised to maximum 1, ``C`` carrying the three maxima);
    the rows and groups left out hold codes that round to 0; the file is smaller."""
    path = tmp_path / f"q{bits}.npz"
    save_tiles(wc, path, code_bits=bits)
    back = load_tiles(path)
    header = json.loads(str(np.load(path)["header"]))
    # no vertex pyramids (compress_tiles): version 2
    assert header["version"] == 2 and header["settings"]["code_bits"] == bits
    assert back.block == wc.block and back.k0 == wc.k0
    # the codes are held as stored (the kernels read them): less than the float32 factors
    assert back.pack.nbytes < wc.pack.nbytes and back.pack.cq.dtype == CODE_DTYPES[bits]
    assert back.nbytes == back.wang.nbytes + back.pack.nbytes + back.mean.nbytes \
        + back.tile_means.nbytes + back.means_px.nbytes + back.moment_sat.nbytes
    half = 0.5 / (2**bits - 1)
    tol = half + 1e-6  # float32 decoding
    for lv in range(wc.n_levels):
        A, Bf, C = (x.astype(np.float64) for x in wc.images[lv])
        A2, B2, C2 = (x.astype(np.float64) for x in back.images[lv])
        ma, mb, mc = A.max(-1), Bf.max(-1), C.max(axis=(1, 2))
        scale = ma * mb * mc  # (16, nb^2, rank)
        live = np.abs(A2).max(axis=(2, 3)) > 0
        assert live.any() and np.all(A2.max(-1)[live] <= 1.0)
        for f, f2, m in ((A, A2, ma), (Bf, B2, mb)):
            norm = np.divide(f, m[..., None], out=np.zeros_like(f), where=m[..., None] > 0)
            assert np.all(np.abs(f2 - norm)[live] <= tol)
        # C: the stored product's third factor, relative to the component's scale, everywhere
        # (dropped rows and dead groups decode to 0 and were below half a step)
        err = np.abs(C2 - C * (ma * mb)[:, None, None])
        assert np.all(err <= tol * scale[:, None, None] + 1e-30)
        assert np.all(C2.transpose(0, 3, 1, 2, 4)[~live] == 0)
    np.testing.assert_allclose(back.tile_means, wc.tile_means, rtol=1e-6, atol=0)
    np.testing.assert_array_equal(back.mean, back.tile_means.astype(np.float64).mean(axis=0))
    # the queries see the decoded pyramids: close to the float32 ones
    for c, sp in FOOTPRINTS[1:3]:
        a, b = ndf_image(wc, c, sp), ndf_image(back, c, sp)
        assert np.linalg.norm(b - a) / np.linalg.norm(a) < (2e-2 if bits == 8 else 1e-4)
    path1 = tmp_path / "v1.npz"
    save_tiles(wc, path1, code_bits=0)
    assert path.stat().st_size < path1.stat().st_size


def test_encode_level_drops_zero_rows_and_groups():
    """Rows whose codes are all 0 are not stored; a group without kept rows is not stored."""
    rng = np.random.default_rng(0)
    A = rng.uniform(0, 1, (16, 4, 2, 3))
    C = rng.uniform(0, 1, (16, 3, 3, 4, 2))
    C[0, :, :, 1] = 0.0  # group (0, 1) dead
    C[2, 1, 1, 3] = 1e-9  # a row below half a step of its components' maxima
    enc = encode_level(A, A, C, 8)
    assert enc["c"].shape == (16 * 9 * 4 - 9 - 1, 2) and enc["a"].shape == (16 * 4 - 1, 2, 3)
    assert enc["c"].dtype == enc["a"].dtype == np.uint8 and enc["c_scale"].dtype == np.float32
    assert encode_level(A, A, C, 16)["c"].dtype == np.uint16
    with pytest.raises(PrefilterError, match="code_bits: expected 8 or 16, got 12"):
        encode_level(A, A, C, 12)


def test_deterministic_bytes(wn, wc, tmp_path):
    """Same input, same file bytes (both versions)."""
    for k, (w, bits) in enumerate(((wn, 8), (wc, 0), (wc, 8), (wc, 16))):
        save_tiles(w, tmp_path / f"a{k}.npz", code_bits=bits)
        save_tiles(w, tmp_path / f"b{k}.npz", code_bits=bits)
        assert (tmp_path / f"a{k}.npz").read_bytes() == (tmp_path / f"b{k}.npz").read_bytes()
    # an uncompressed pyramid is written in version 1 whatever code_bits
    assert (tmp_path / "a0.npz").read_bytes() == _saved_bytes(wn, tmp_path / "u.npz", 0)


def test_bake_compressed_level_by_level_equals_compress_tiles(wn, wc, tmp_path):
    """bake_tiles(rank=...) compresses each level as soon as the next is filtered (lower memory
    peak): the same factors and errors as compress_tiles of the uncompressed bake, the same
    file bytes."""
    wb = bake_tiles(wn.wang, ndf_res=R, support=0.5, intrinsic_roughness=0.01, rank=2, block=8,
                    n_iter_max=5)
    assert wb.cp_error == wc.cp_error and wb.block == wc.block
    for a, b in zip(wb.images, wc.images):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    # the same bytes without the vertex pyramids (compress_tiles has none)
    wt_only = replace(wb, vertex_images=(), vertex_cp_error=())
    for bits in (0, 8):
        assert _saved_bytes(wt_only, tmp_path / "b.npz", bits) == _saved_bytes(
            wc, tmp_path / "c.npz", bits)
    with pytest.raises(PrefilterError, match="block: expected a divisor of ndf_res 16, got 5"):
        bake_tiles(wn.wang, ndf_res=R, rank=2, block=5)


def test_inconsistent_v3_layouts(wn, tmp_path):
    """Malformed version-3 files (vertex and coarse pyramids): each rejected with the file and
    the field named."""
    wb = bake_tiles(wn.wang, ndf_res=R, support=0.5, intrinsic_roughness=0.01, rank=2, block=4,
                    n_iter_max=5, angular_pool=2)
    src = tmp_path / "v3.npz"
    save_tiles(wb, src)
    back = load_tiles(src)
    assert back.vertex_packed is not None and back.coarse is not None
    cases = {
        r"header.settings.vertex_k0: expected one per level": _edit_settings(vertex_k0=[0]),
        r"header.settings.vertex_crops: expected crop sizes >= 1":
            _edit_settings(vertex_crops=[0] * wb.n_levels),
        r"header.settings.angular_pool: expected 0 or a divisor p >= 2 of ndf_res 16":
            _edit_settings(angular_pool=3),
        r"header.settings.coarse_cp_error: expected \d+ entries, got 0":
            _edit_settings(coarse_cp_error=[]),
        r"header field missing or invalid \(KeyError: 'vertex_k0'\)":
            lambda a: _edit_header(settings={k: v for k, v in json.loads(
                str(a["header"]))["settings"].items() if k != "vertex_k0"})(a),
        r"vc_0, va_0, vb_0, vc_scale_0: expected \d+ rows \(kept rows of vmask_0\)":
            _replace("vc_0", lambda c: c[:-1]),
        r"gvc_0, gva_0, gvb_0, gvc_scale_0: expected \d+ rows \(kept rows of gvmask_0\)":
            _replace("gvc_0", lambda c: c[:-1]),
        r"missing arrays \['gc_1'\]": lambda a: a.pop("gc_1"),
    }
    for k, (msg, edit) in enumerate(cases.items()):
        with pytest.raises(TableFileError, match=rf"{k}.npz: {msg}"):
            load_tiles(_rewrite(src, tmp_path / f"{k}.npz", edit))


def test_round_trip_vertex_pyramids(wn, tmp_path):
    """A compressed bake's vertex pyramids: version 3 (each vertex level's codes as the tiles'),
    the queries of the loaded file within the codes' rounding of the baked ones; float32 files
    (version 1) leave them out and the queries compute the dependent texels exactly."""
    wb = bake_tiles(wn.wang, ndf_res=R, support=0.5, intrinsic_roughness=0.01, rank=4, block=8,
                    n_iter_max=20)
    assert len(wb.vertex_images) == wb.n_levels == len(wb.vertex_cp_error)
    path = tmp_path / "v3.npz"
    save_tiles(wb, path)
    header = json.loads(str(np.load(path)["header"]))
    assert header["version"] == VERSION == 4
    assert header["settings"]["vertex_cp_error"] == list(wb.vertex_cp_error)
    back = load_tiles(path)
    assert back.vertex_packed is not None and back.vertex_pack.cq.dtype == np.uint8
    assert back.nbytes == back.wang.nbytes + back.pack.nbytes + back.vertex_pack.nbytes \
        + back.mean.nbytes + back.tile_means.nbytes + back.means_px.nbytes + back.moment_sat.nbytes
    rng = np.random.default_rng(5)
    c = rng.uniform(-20, 40, (400, 2))
    sp = rng.uniform(wb.min_sigma, wb.wide_sigma, 400)
    q = rng.uniform(-0.3, 0.3, (400, 2))
    a, b = ndf_points(wb, c, sp, q), ndf_points(back, c, sp, q)
    assert np.linalg.norm(b - a) / np.linalg.norm(a) < 2e-2
    save_tiles(wb, tmp_path / "v1.npz", code_bits=0)
    v1 = load_tiles(tmp_path / "v1.npz")
    assert v1.vertex_images == () and v1.vertex_pack is None
    exact = ndf_points(replace(wb, vertex_images=()), c, sp, q)
    np.testing.assert_array_equal(ndf_points(v1, c, sp, q), exact)
    # the moment tables: stored in version 4, computed from the tiles for older files (the same
    # bytes: the same function of the same tiles)
    np.testing.assert_array_equal(back.moment_sat, wb.moment_sat)
    np.testing.assert_array_equal(v1.moment_sat, wb.moment_sat)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k not in (META_KEY, "moment_sat")}
    h = json.loads(str(arrays["header"]))
    h["version"] = 3
    del h["arrays"]["moment_sat"]
    arrays["header"] = np.array(json.dumps(h, sort_keys=True))
    save_npz_atomic(tmp_path / "v3.npz", format_name=FORMAT, format_version=3, **arrays)
    v3 = load_tiles(tmp_path / "v3.npz")
    np.testing.assert_array_equal(v3.moment_sat, wb.moment_sat)
    wide = rng.uniform(wb.wide_sigma, wb.uniform_sigma, 400)
    np.testing.assert_array_equal(ndf_points(v3, c, wide, q), ndf_points(back, c, wide, q))


@pytest.mark.parametrize("shape", [(3, 8, 8, 361), (1, 4, 4, 10), (5, 16, 16, 169)])
def test_sum_squares_of_float32_tensors_in_float64(shape):
    """The bake's CP error denominator, summed chunk by chunk from float32 tensors, is the sum of
    squares of their float64 copy (to rounding: the chunks change the order of additions)."""
    from prefilter.glints.wang_ndf import _sum_squares

    x = np.random.default_rng(1).random(shape).astype(np.float32)
    x64 = x.astype(np.float64)
    assert _sum_squares(x) == pytest.approx(float(np.einsum("gijk,gijk->", x64, x64)),
                                            rel=1e-12)


def _saved_bytes(w, path, bits):
    save_tiles(w, path, code_bits=bits)
    return path.read_bytes()


def _rewrite(src, dst, edit):
    """Copy the .npz ``src`` to ``dst`` with ``edit(arrays)`` applied (``__meta__`` unchanged,
    so a content edit that keeps the layout must fail on the checksum)."""
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    edit(arrays)
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)
    return dst


def _edit_header(**changes):
    def edit(arrays):
        h = json.loads(str(arrays["header"]))
        h.update(changes)
        arrays["header"] = np.array(json.dumps(h))
    return edit


def test_wrong_version_and_format(saved, tmp_path):
    p = _rewrite(saved, tmp_path / "v.npz", _edit_header(version=VERSION + 1))
    with pytest.raises(TableFileError, match=rf"v.npz: header.version: expected 1, 2, 3 or "
                                             rf"{VERSION}, got {VERSION + 1}"):
        load_tiles(p)
    p = _rewrite(saved, tmp_path / "f.npz", _edit_header(format="prefilter-glints"))
    with pytest.raises(TableFileError, match="header.format: expected 'prefilter-glints-wang'"):
        load_tiles(p)


def test_truncated_and_corrupt_bytes(saved, tmp_path):
    raw = saved.read_bytes()
    for n in (0, 100, len(raw) // 2, len(raw) - 10):
        p = tmp_path / f"t{n}.npz"
        p.write_bytes(raw[:n])
        with pytest.raises(TableFileError, match=f"t{n}.npz: unreadable"):
            load_tiles(p)
    flipped = bytearray(raw)
    flipped[len(raw) // 3] ^= 0x40  # inside the first level's images
    (tmp_path / "x.npz").write_bytes(bytes(flipped))
    with pytest.raises(TableFileError, match="x.npz"):
        load_tiles(tmp_path / "x.npz")
    with pytest.raises(TableFileError, match="file not found"):
        load_tiles(tmp_path / "missing.npz")


def test_checksum_mismatch(saved, tmp_path):
    def edit(arrays):
        arrays["images_1"] = arrays["images_1"].copy()
        arrays["images_1"][3, 2, 2, 5, 5] += 1.0

    with pytest.raises(TableFileError, match=rf"{META_KEY}.sha256: checksum mismatch"):
        load_tiles(_rewrite(saved, tmp_path / "s.npz", edit))


def test_inconsistent_layouts(saved, tmp_path):
    cases = {
        "missing arrays": lambda a: a.pop("mean"),
        "unknown arrays": lambda a: a.update(extra=np.zeros(2)),
        "images_0: expected float32": lambda a: a.update(images_0=a["images_0"][:, :-1]),
        "header.tile: expected an even": _edit_header(tile=7),
        "header field missing": _edit_header(settings={}),
        "tiles: expected unit normals": lambda a: a.update(tiles=2 * a["tiles"]),
        "mean: expected finite": lambda a: a.update(mean=np.full_like(a["mean"], np.nan)),
        "dependent: expected the dependent texels": lambda a: a.update(
            dependent=a["dependent"][::-1].copy()),
        "header: expected a JSON object": lambda a: a.update(header=np.array("[1, 2]")),
    }
    for k, (msg, edit) in enumerate(cases.items()):
        with pytest.raises(TableFileError, match=msg):
            load_tiles(_rewrite(saved, tmp_path / f"{k}.npz", edit))


@pytest.fixture(scope="module")
def saved2(wc, tmp_path_factory):
    path = tmp_path_factory.mktemp("wang2") / "tiles2.npz"
    save_tiles(wc, path)
    return path


def _edit_settings(**changes):
    def edit(arrays):
        h = json.loads(str(arrays["header"]))
        h["settings"].update(changes)
        arrays["header"] = np.array(json.dumps(h))
    return edit


def _replace(name, value):
    """Replace array ``name`` and its header entry (so only the targeted check can fail)."""
    def edit(arrays):
        arrays[name] = value(arrays.get(name))
        h = json.loads(str(arrays["header"]))
        h["arrays"][name] = {"dtype": arrays[name].dtype.str, "shape": list(arrays[name].shape)}
        arrays["header"] = np.array(json.dumps(h))
    return edit


def test_inconsistent_v2_layouts(saved2, tmp_path):
    """Malformed version-2 files: each rejected with the file and the field named."""
    assert load_tiles(saved2).block == 8
    nl = load_tiles(saved2).n_levels
    assert nl >= 2
    cases = {
        r"header.settings.code_bits: expected 8 or 16 with block > 0 \(version 2\), got 12":
            _edit_settings(code_bits=12),
        rf"header.settings.crops: expected {nl} crop sizes >= 1 \(one per level\), got \[":
            _edit_settings(crops=[3]),  # one entry: fewer than the fixture's levels
        r"header field missing or invalid \(KeyError: 'crops'\)":
            lambda a: _edit_header(settings={k: v for k, v in json.loads(
                str(a["header"]))["settings"].items() if k != "crops"})(a),
        r"mask_0: expected uint8 of shape \(\d+,\) as in the header":
            _replace("mask_0", lambda m: m[:-1]),
        r"c_0, a_0, b_0, c_scale_0: expected \d+ rows \(kept rows of mask_0\) ":  # a bit flipped
            _replace("mask_0", lambda m: np.concatenate([m[:-1], [m[-1] ^ 1]]).astype(np.uint8)),
        r"c_0, a_0, b_0, c_scale_0: expected \d+ rows \(kept rows of mask_0\) and \d+ live "
        r"groups, got":
            _replace("c_0", lambda c: c[:-1]),
        r"a_1: expected uint8 of shape \(n, 2, 8\) as in the header":
            _replace("a_1", lambda x: x.astype(np.uint16)),
        r"c_scale_1: expected finite values":
            _replace("c_scale_1", lambda x: np.full_like(x, np.inf)),
        r"c_scale_0: expected non-negative values":
            _replace("c_scale_0", lambda x: -x),
        r"tile_means: expected float32 of shape \(16, 16, 16\)":
            _replace("tile_means", lambda x: x.astype(np.float64)),
        r"missing arrays \['c_1'\]": lambda a: a.pop("c_1"),
        r"header.arrays: expected \[": _replace("mean", lambda _: np.zeros((R, R))),
    }
    for k, (msg, edit) in enumerate(cases.items()):
        with pytest.raises(TableFileError, match=rf"{k}.npz: {msg}"):
            load_tiles(_rewrite(saved2, tmp_path / f"{k}.npz", edit))

    def flip_code(arrays):
        arrays["c_1"] = arrays["c_1"].copy()
        arrays["c_1"][0, 0] ^= 1

    with pytest.raises(TableFileError, match=rf"{META_KEY}.sha256: checksum mismatch"):
        load_tiles(_rewrite(saved2, tmp_path / "s.npz", flip_code))


def test_save_validation(wn, wc, tmp_path):
    with pytest.raises(PrefilterError, match="wn: expected a TiledNDF"):
        save_tiles(wn.wang, tmp_path / "a.npz")
    with pytest.raises(PrefilterError, match=r"code_bits: expected one of \(0, 8, 16\), got 4"):
        save_tiles(wc, tmp_path / "a.npz", code_bits=4)
    assert not (tmp_path / "a.npz").exists()


def test_cli_bake_glints_wang(tmp_path):
    from click.testing import CliRunner

    from prefilter.cli import cli

    np.save(tmp_path / "n.npy", sinusoid(16, px=16, py=8))
    out = tmp_path / "w.npz"
    res = CliRunner().invoke(cli, ["bake", "glints-wang", str(tmp_path / "n.npy"), "-o", str(out),
                                   "--tile", "8", "--band", "2", "--rank", "2", "--ndf-res", "16",
                                   "--block", "8", "--iters", "5", "--seed", "4", "--quiet"])
    assert res.exit_code == 0, res.output
    back = load_tiles(out)
    assert back.wang.size == 8 and back.block == 8 and back.images[0][0].shape[2] == 2
    summary = json.loads(res.output.strip().splitlines()[-1])
    assert summary["tiles"] == 16 and summary["memory_bytes"] == back.nbytes
    assert summary["file_bytes"] == out.stat().st_size and summary["code_bits"] == 8
    # --code-bits 16 / 0: the same pyramids stored wider (version 2) or as float32 (version 1)
    def recon(w):  # the level-0 contribution images from the CP triple
        A, Bf, C = w.images[0]
        return np.einsum("tgry,tgrx,tijgr->tijgyx", A, Bf, C)

    sizes, images = {}, {"8": recon(back)}
    for bits in ("16", "0"):
        o = tmp_path / f"w{bits}.npz"
        r = CliRunner().invoke(cli, ["bake", "glints-wang", str(tmp_path / "n.npy"), "-o", str(o),
                                     "--tile", "8", "--band", "2", "--rank", "2", "--ndf-res",
                                     "16", "--block", "8", "--iters", "5", "--seed", "4",
                                     "--code-bits", bits, "--quiet"])
        assert r.exit_code == 0, r.output
        assert json.loads(r.output.strip().splitlines()[-1])["code_bits"] == int(bits)
        sizes[bits] = o.stat().st_size
        images[bits] = recon(load_tiles(o))
    top = images["0"].max()
    np.testing.assert_allclose(images["16"], images["0"], rtol=0, atol=1e-4 * top)  # 9e-6 seen
    np.testing.assert_allclose(images["8"], images["0"], rtol=0, atol=1e-2 * top)  # 2.4e-3 seen
    assert out.stat().st_size < sizes["16"] < sizes["0"]
    # the same command, same seed: the same tiles and pyramids
    res2 = CliRunner().invoke(cli, ["bake", "glints-wang", str(tmp_path / "n.npy"), "-o",
                                    str(tmp_path / "w2.npz"), "--tile", "8", "--band", "2",
                                    "--rank", "2", "--ndf-res", "16", "--block", "8", "--iters",
                                    "5", "--seed", "4", "--quiet"])
    assert res2.exit_code == 0, res2.output
    np.testing.assert_array_equal(load_tiles(tmp_path / "w2.npz").images[0][2], back.images[0][2])
    bad = CliRunner().invoke(cli, ["bake", "glints-wang", str(tmp_path / "n.npy"), "-o",
                                   str(tmp_path / "w3.npz"), "--tile", "7"])
    assert bad.exit_code != 0 and "tile" in str(bad.exception) + bad.output


def test_bakes_share_their_options_with_per_command_defaults():
    """``glints`` and ``glints-wang`` declare the shared options once (commands.shared_options),
    each with its own defaults, help and position in ``--help``."""
    from prefilter.glints.bake import BAKE_SETTINGS
    from prefilter.glints.commands import bake_glints, bake_glints_wang

    shared = ("ndf_res", "block", "support", "roughness", "iters", "seed", "quiet")
    opts = {c.name: {p.name: p for p in c.params} for c in (bake_glints, bake_glints_wang)}
    st = BAKE_SETTINGS  # glints: the render method's bake
    want = {"glints": (st["ndf_res"], st["block"], st["support"], st["intrinsic_roughness"],
                       st["n_iter_max"], st["seed"], False),
            "glints-wang": (64, 8, 0.5, 0.005, 100, 0, False)}
    for name, defaults in want.items():
        assert tuple(opts[name][k].default for k in shared) == defaults
        assert opts[name]["quiet"].is_flag and opts[name]["block"].show_default
    assert opts["glints"]["seed"].help is None
    assert opts["glints-wang"]["seed"].help.startswith("Seeds the tile synthesis")
    order = [[p.name for p in c.params if p.name in shared]
             for c in (bake_glints, bake_glints_wang)]
    assert order == [list(shared), ["block", "ndf_res", *shared[2:]]]
