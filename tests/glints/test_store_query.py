"""Bake a small map, then check queries against the uncompressed NDF images, the range-query
proposition, the loader's validation and the CLI."""

import json

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints import pndf_image
from prefilter.glints.bake import EXACT_BUDGET_RULE, bake
from prefilter.glints.query import block_means, point, range_mean
from prefilter.glints.store import (ARRAYS, PREFIX_MAX, block_index_from_mask, decode,
                                    decode_v2, encode, encode_v2, factor_codes, load, pack_mask,
                                    save)

R, S, BLK = 32, 0.4, 8


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    nm = sinusoid(32, ax=0.25, ay=0.2, px=16, py=8)
    out = tmp_path_factory.mktemp("gl") / "map.npz"
    summary = bake(nm, out, rank=16, ndf_res=R, block=BLK, support=S, cell=16, converge=0.0,
                   n_iter_max=300, tol=1e-7, progress=False)
    return nm, out, summary, load(out)


def pixel_grid():
    h = 2 * S / R
    x = (np.arange(R) + 0.5) * h - S
    X, Y = np.meshgrid(x, x)
    return np.stack([X, Y], -1), h


def test_point_queries_reproduce_the_ndf_images(baked):
    nm, _, summary, gm = baked
    s, _ = pixel_grid()
    pyr = gm.pyramid
    c = pyr.centers(1)[1, 0]
    ref = pndf_image(nm, c, pyr.sigma(1), R, S)
    got = point(gm, c, pyr.sigma(1), s)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 2 * max(summary["rel_l2_error"], 0.01)
    assert np.all(got >= 0)


def test_summary_error_is_the_measured_error(baked):
    nm, _, summary, gm = baked
    s, _ = pixel_grid()
    pyr = gm.pyramid
    num = den = 0.0
    for lv in range(pyr.n_levels):
        cen = pyr.centers(lv).reshape(-1, 2)
        ref = pndf_image(nm, cen, pyr.sigma(lv), R, S)
        got = point(gm, cen[:, None, None, :], pyr.sigma(lv), s[None])
        e2, n2 = np.sum((got - ref) ** 2), np.sum(ref**2)
        assert np.sqrt(e2 / n2) == pytest.approx(summary["rel_l2_error_per_level"][lv],
                                                  rel=0.02, abs=1e-3)
        num += e2
        den += n2
    assert np.sqrt(num / den) == pytest.approx(summary["rel_l2_error"], rel=0.02, abs=1e-3)


def test_range_equals_mean_of_point_queries(baked):
    """The appendix proposition, over rectangles spanning several blocks."""
    _, _, _, gm = baked
    s, h = pixel_grid()
    rng = np.random.default_rng(0)
    for _ in range(6):
        i0, j0 = rng.integers(0, R - 1, 2)
        i1, j1 = rng.integers(i0 + 1, R + 1), rng.integers(j0 + 1, R + 1)
        c, sp = rng.uniform(0, 32, 2), rng.uniform(3, 40)
        pts = point(gm, c, sp, s[i0:i1, j0:j1])
        lo = np.array([j0 * h - S, i0 * h - S])
        hi = np.array([j1 * h - S, i1 * h - S])
        assert range_mean(gm, c, sp, lo, hi) == pytest.approx(pts.mean(), rel=1e-5, abs=1e-9)


def test_fractional_range_and_vectorisation(baked):
    _, _, _, gm = baked
    lo = np.array([[-0.13, -0.05], [0.3, 0.35]])
    hi = np.array([[0.021, 0.17], [0.6, 0.7]])  # the second leaves the support
    c = np.array([[5.0, 9.0], [20.0, 1.0]])
    got = range_mean(gm, c, 7.0, lo, hi)
    n = 200
    for q in range(2):
        t = (np.arange(n) + 0.5) / n
        X, Y = np.meshgrid(lo[q, 0] + t * (hi[q, 0] - lo[q, 0]),
                           lo[q, 1] + t * (hi[q, 1] - lo[q, 1]))
        dense = point(gm, c[q], 7.0, np.stack([X, Y], -1)).mean()
        assert got[q] == pytest.approx(dense, rel=1e-2, abs=1e-6)


def test_block_means_match_range_over_each_block(baked):
    _, _, _, gm = baked
    h = 2 * S / R
    img = 3
    means = block_means(gm, img)
    pyr = gm.pyramid
    c = pyr.centers(0).reshape(-1, 2)[img]
    for bi, bj in [(1, 1), (2, 1), (0, 3)]:
        lo = np.array([bj * BLK * h - S, bi * BLK * h - S])
        rng_ = range_mean(gm, c, pyr.sigma(0), lo, lo + BLK * h)
        assert means[bi, bj] == pytest.approx(rng_, rel=1e-4, abs=1e-9)


def test_loader_rejects_bad_files(baked, tmp_path):
    _, out, _, gm = baked
    bad = tmp_path / "bad.npz"
    with np.load(out) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    for mutate, match in [
        (lambda a, h: h.update(version=99), "version"),
        (lambda a, h: a.pop("c"), "missing"),
        (lambda a, h: a.update(c_scale=-a["c_scale"] - 1), "c_scale"),
        (lambda a, h: a.update(c=a["c"].astype(np.float16)), "uint8"),
        (lambda a, h: a.update(c=a["c"][:-1]), "kept blocks"),
        (lambda a, h: a.update(ranks=a["ranks"] + 1), "sum of ranks"),
        (lambda a, h: a.update(block_mask=a["block_mask"][:-1]), "block_mask"),
        (lambda a, h: a.update(image_cell=a["image_cell"] + 10**6), "image_cell"),
        (lambda a, h: h["ndf"].update(rank=1), "ranks"),
        (lambda a, h: h.update(version=1), "missing"),  # a version-3 layout labelled 1
    ]:
        a = dict(arrays)
        h = json.loads(json.dumps(header))
        mutate(a, h)
        a["header"] = np.array(json.dumps(h))
        np.savez(bad, **a)
        with pytest.raises(TableFileError, match=match):
            load(bad)
    bad.write_bytes(b"not a zip")
    with pytest.raises(TableFileError):
        load(bad)


def test_save_roundtrip_is_deterministic(baked, tmp_path):
    """A version-1 file (float32 prefix sums, written without the encoded arrays) loads to the
    same arrays as the version-3 file it came from."""
    _, out, _, gm = baked
    save(tmp_path / "again.npz", gm)
    g2 = load(tmp_path / "again.npz")
    assert g2.header["version"] == 1 and gm.header["version"] == 3
    for k in ARRAYS:
        np.testing.assert_array_equal(getattr(g2, k), getattr(gm, k))
    # what is counted is what is on disk: the 8-bit factors, not the float32 prefix sums
    assert gm.compressed_bytes < 0.35 * g2.compressed_bytes


def test_version2_files_still_load(baked, tmp_path):
    """A version-2 file (float16 factors of one rank) of the same factors loads to the same
    in-memory arrays up to float16 rounding."""
    _, _, _, gm = baked
    nb = gm.block_index.shape[1]
    G = gm.A.shape[0]
    _, rows = block_index_from_mask(pack_mask(gm.block_index >= 0), gm.image_cell, nb, G)
    a, b = np.diff(gm.A.astype(np.float64), axis=2), np.diff(gm.Bp.astype(np.float64), axis=2)
    save(tmp_path / "v2.npz", gm, encode_v2(a, b, gm.C.astype(np.float64), rows))
    g2 = load(tmp_path / "v2.npz")
    assert g2.header["version"] == 2 and g2.ranks is None
    np.testing.assert_array_equal(g2.block_index, gm.block_index)
    np.testing.assert_allclose(g2.A, gm.A, atol=2e-3)
    np.testing.assert_allclose(g2.C, gm.C, rtol=2e-3, atol=1e-3 * gm.C.max())


def test_float16_encoding_error_is_rounding():
    """decode_v2(encode_v2(.)) == the float64 factors to float16 rounding (2^-11 relative),
    including block sums far above float16's range (per-group scales) and empty groups."""
    rng = np.random.default_rng(3)
    G, Rk, Bs = 5, 4, 8
    a = rng.random((G, Rk, Bs))
    a /= a.sum(axis=-1, keepdims=True)
    b = rng.random((G, Rk, Bs))
    b /= b.sum(axis=-1, keepdims=True)
    rows = np.array([0, 3, 3, 10, 11, 11])
    c = rng.random((11, Rk)) * 10.0 ** rng.integers(-3, 7, (11, 1))
    A, Bp, C = decode_v2(**encode_v2(a, b, c, rows))
    np.testing.assert_allclose(np.diff(A, axis=-1), a, rtol=2e-3, atol=1e-7)
    np.testing.assert_allclose(np.diff(Bp, axis=-1), b, rtol=2e-3, atol=1e-7)
    np.testing.assert_allclose(A[..., -1], 1.0, rtol=1e-6)
    gmax = np.array([c[r0:r1].max(axis=0) if r1 > r0 else np.zeros(Rk)
                     for r0, r1 in zip(rows[:-1], rows[1:])])
    per_row = np.repeat(gmax, np.diff(rows), axis=0)
    assert np.all(np.abs(C - c) <= 1e-3 * per_row)


@pytest.mark.parametrize("bits", [8, 16])
def test_8bit_encoding_error_is_rounding(bits):
    """decode(encode(.)) of groups of different ranks (one empty) == the factors up to the
    rounding bounds of ``q = 2^bits - 1`` steps: ``|c' - c| <= m_c / 2q``; for ``a``
    (renormalised after rounding, ``q_i = q a_i / m + d_i``, ``|d_i| <= 1/2``):
    ``|a' - a| <= (1 / k) (1/2 + a B / 2) / (1 - B / 2k)`` with ``k = q / m`` steps per unit,
    or ``k = PREFIX_MAX - B / 2`` where that would let the row's codes sum past ``PREFIX_MAX``
    (16-bit codes: store.factor_codes)."""
    rng = np.random.default_rng(4)
    Bs, ranks, ks = 8, [3, 0, 5, 1], [4, 2, 7, 3]
    groups = []
    for r, k in zip(ranks, ks):
        a = rng.random((r, Bs)) ** 4
        a /= a.sum(axis=1, keepdims=True)
        b = rng.random((r, Bs))
        b /= b.sum(axis=1, keepdims=True)
        groups.append((a, b, rng.random((k, r)) * 10.0 ** rng.integers(-3, 7, (1, r))))
    enc = encode(groups, bits)
    q, dt = (2**bits - 1), {8: np.uint8, 16: np.uint16}[bits]
    assert enc["a"].dtype == enc["b"].dtype == enc["c"].dtype == dt
    rows = np.concatenate([[0], np.cumsum(ks)])
    A, Bp, C = decode(**enc, group_rows=rows, width=6)
    assert A.shape == (4, 6, Bs + 1) and C.shape == (rows[-1], 6)
    for g, (a, b, c) in enumerate(groups):
        r = ranks[g]
        for f, P in ((a, A), (b, Bp)):
            k = np.minimum(q / f.max(axis=1, keepdims=True), PREFIX_MAX - Bs // 2)
            bound = (0.5 + 0.5 * Bs * f) / (k - Bs / 2)
            # float32 prefix sums add ~1e-7 (more than 16-bit codes' own rounding)
            assert np.all(np.abs(np.diff(P[g, :r].astype(np.float64), axis=1) - f)
                          <= bound + (1e-6 if bits == 8 else 2e-7))
            assert np.all(P[g, r:] == 0)
        Cg = C[rows[g]:rows[g + 1]].astype(np.float64)
        assert np.all(np.abs(Cg[:, :r] - c) <= c.max(axis=0) / (2 * q) * (1 + 1e-5))
        assert np.all(Cg[:, r:] == 0)


def test_block_index_from_mask_numbers_rows_by_group_then_image():
    rng = np.random.default_rng(5)
    N, nb = 12, 2
    kept = rng.random((N, nb, nb)) < 0.6
    cell = np.sort(rng.integers(0, 3, N)).astype(np.int32)
    index, rows = block_index_from_mask(pack_mask(kept), cell, nb, 3 * nb * nb)
    expect = np.full((N, nb, nb), -1)
    k = 0
    for g in range(3 * nb * nb):  # brute force: groups in order, images in order
        c, blk = divmod(g, nb * nb)
        for n in range(N):
            if cell[n] == c and kept[n].ravel()[blk]:
                expect[n].ravel()[blk] = k
                k += 1
        assert rows[g + 1] == k
    np.testing.assert_array_equal(index, expect)


def test_bake_resumes_from_parts(tmp_path):
    """A bake killed after some chunks resumes from them and gives the same file."""
    nm = sinusoid(16, px=16, py=8)
    kw = dict(rank=4, ndf_res=16, block=8, support=S, cell=8, n_iter_max=20, progress=False)
    out = tmp_path / "a.npz"
    s1 = bake(nm, out, keep_parts=True, **kw)
    first = load(out)
    parts = tmp_path / "a.npz.parts"
    # forget one level-0 chunk and one compressed cell, as if the bake had died there
    for chunk in ("000000", "100001", "099999", "500002"):
        (parts / f"{chunk}.npz").unlink()
    out.unlink()
    s2 = bake(nm, out, **kw)
    again = load(out)
    assert s2["rel_l2_error"] == s1["rel_l2_error"]
    for k in ARRAYS:
        np.testing.assert_array_equal(getattr(again, k), getattr(first, k))
    assert not parts.exists()


def test_bake_parts_keyed_by_fit_version(tmp_path, monkeypatch):
    """Checkpoints record the CP fit's version: parts fitted by another version are discarded,
    not resumed from."""
    from prefilter.glints import cp as cpmod

    nm = sinusoid(16, px=16, py=8)
    kw = dict(rank=2, ndf_res=16, block=8, support=S, cell=8, n_iter_max=3, progress=False,
              keep_parts=True)
    out = tmp_path / "a.npz"
    bake(nm, out, **kw)
    meta = tmp_path / "a.npz.parts" / "settings.json"
    assert json.loads(meta.read_text())["cp_fit"] == cpmod.FIT_VERSION
    monkeypatch.setattr(cpmod, "FIT_VERSION", cpmod.FIT_VERSION + 1)
    out.unlink()
    bake(nm, out, **kw)
    assert json.loads(meta.read_text())["cp_fit"] == cpmod.FIT_VERSION
    assert "exact_budget" not in json.loads(meta.read_text())
    # with exact levels the parts also record the budget rule
    out.unlink()
    bake(nm, out, exact_from_level=1, **kw)
    assert json.loads(meta.read_text())["exact_budget"] == EXACT_BUDGET_RULE


def test_bake_rank_errors(tmp_path):
    nm = sinusoid(16, px=16, py=8)
    with pytest.raises(PrefilterError, match="max_rank"):
        bake(nm, tmp_path / "x.npz", rank=8, max_rank=4, ndf_res=16, block=8, cell=8,
             progress=False)


def test_query_input_errors(baked):
    _, _, _, gm = baked
    with pytest.raises(PrefilterError, match="s_max"):
        range_mean(gm, [1, 1], 4.0, [0.1, 0.1], [0.0, 0.2])
    with pytest.raises(PrefilterError, match="gm"):
        point(None, [1, 1], 4.0, [0, 0])
    with pytest.raises(PrefilterError, match="interp"):
        point(gm, [1, 1], 4.0, [0, 0], interp="cubic")
    from prefilter.glints.query import check_interp

    check_interp("resample")
    with pytest.raises(PrefilterError, match=r"interp: expected one of"):
        check_interp("bilinear")


def test_cli_bake(tmp_path):
    from click.testing import CliRunner

    from prefilter.glints.commands import bake_glints

    np.save(tmp_path / "n.npy", sinusoid(16, px=16, py=8))
    res = CliRunner().invoke(bake_glints, [str(tmp_path / "n.npy"), "-o", str(tmp_path / "o.npz"),
                                           "--rank", "4", "--ndf-res", "16", "--block", "8",
                                           "--cell", "8", "--iters", "10", "--quiet"])
    assert res.exit_code == 0, res.output
    gm = load(tmp_path / "o.npz")
    assert "ratio" in res.output and gm.header["settings"]["rank"] == 4
    assert gm.rank == gm.ranks.max() <= 12  # --max-rank defaults to 3 x --rank
    res = CliRunner().invoke(bake_glints, [str(tmp_path / "n.npy"), "-o", str(tmp_path / "p.npz"),
                                           "--rank", "4", "--ndf-res", "16", "--block", "8",
                                           "--cell", "8", "--iters", "10", "--quiet",
                                           "--code-bits", "16", "--ndf-truncation", "6",
                                           "--footprint-truncation", "5", "--c-bits", "8",
                                           "--exact-from-level", "1", "--exact-cell", "1"])
    assert res.exit_code == 0, res.output
    gm = load(tmp_path / "p.npz")
    st = gm.header["settings"]
    assert (st["code_bits"], st["ndf_truncation"], st["footprint_truncation"]) == (16, 6.0, 5.0)
    assert (st["c_bits"], st["exact_from_level"], st["exact_cell"]) == (8, 1, 1)
    assert gm.codes["a"].dtype == np.uint16 and gm.codes["c"].dtype == np.uint8


def _images_from_codes(gm, images):
    """Float64 NDF images ``(len(images), R, R)`` straight from the stored version-3 codes:
    ``c q_c / 255 * (q_a / S_a) (q_b / S_b)`` per component (the loader's dequantisation and
    renormalisation), independently of the packed arrays the kernels read."""
    cd = gm.codes
    ranks = cd["ranks"].astype(np.int64)
    m0 = np.concatenate([[0], np.cumsum(ranks)])
    a = cd["a"].astype(np.float64)
    b = cd["b"].astype(np.float64)
    a /= np.where(a.sum(1, keepdims=True) > 0, a.sum(1, keepdims=True), 1)
    b /= np.where(b.sum(1, keepdims=True) > 0, b.sum(1, keepdims=True), 1)
    rows = cd["group_rows"]
    c_off = np.concatenate([[0], np.cumsum(np.diff(rows) * ranks)])
    nb = gm.resolution // gm.block
    out = np.zeros((len(images), gm.resolution, gm.resolution))
    for n, img in enumerate(images):
        for bi in range(nb):
            for bj in range(nb):
                k = gm.block_index[img, bi, bj]
                if k < 0:
                    continue
                g = gm.image_cell[img] * nb * nb + bi * nb + bj
                r, m = ranks[g], m0[g]
                start = c_off[g] + (k - rows[g]) * r
                cr = (cd["c"][start:start + r] / float(np.iinfo(cd["c"].dtype).max)
                      * cd["c_scale"][m:m + r])
                out[n, bi * gm.block:(bi + 1) * gm.block, bj * gm.block:(bj + 1) * gm.block] = (
                    np.einsum("r,ri,rj->ij", cr, a[m:m + r], b[m:m + r]))
    return out


@pytest.fixture(scope="module")
def baked16(tmp_path_factory, baked):
    """The map of ``baked`` with 16-bit codes."""
    nm = baked[0]
    out = tmp_path_factory.mktemp("gl16") / "map.npz"
    summary = bake(nm, out, rank=16, ndf_res=R, block=BLK, support=S, cell=16, converge=0.0,
                   n_iter_max=300, tol=1e-7, progress=False, code_bits=16)
    return nm, out, summary, load(out)


@pytest.fixture(scope="module")
def baked16c8(tmp_path_factory, baked):
    """The map of ``baked`` with 16-bit ``a``, ``b`` and 8-bit ``c`` codes."""
    nm = baked[0]
    out = tmp_path_factory.mktemp("gl16c8") / "map.npz"
    summary = bake(nm, out, rank=16, ndf_res=R, block=BLK, support=S, cell=16, converge=0.0,
                   n_iter_max=300, tol=1e-7, progress=False, code_bits=16, c_bits=8)
    return nm, out, summary, load(out)


def test_16bit_factors_8bit_c_bake(baked, baked16, baked16c8):
    """``code_bits=16, c_bits=8``: uint16 ``a``, ``b``, uint8 ``c`` (recorded in the settings),
    ``c`` as many bytes as the 8-bit bake's (about: the budget moves a few groups), and an error
    between the 16-bit and the 8-bit bakes'."""
    _, _, s8, _ = baked
    _, _, s16, _ = baked16
    _, _, sh, gh = baked16c8
    st = gh.header["settings"]
    assert (st["code_bits"], st["c_bits"]) == (16, 8)
    assert gh.codes["a"].dtype == gh.codes["b"].dtype == np.uint16
    assert gh.codes["c"].dtype == np.uint8
    assert 0.9 <= sh["bytes"]["c"] / s8["bytes"]["c"] <= 1.1
    assert 1.8 <= sh["bytes"]["a"] / s8["bytes"]["a"] <= 2.2
    assert s16["rel_l2_error"] * 0.99 <= sh["rel_l2_error"] <= s8["rel_l2_error"] * 1.01
    # the fit's own error (before the codes' rounding): below the stored one, by little with
    # 16-bit codes, by more with 8-bit c codes
    for s in (s8, s16, sh):
        assert 0 < s["rel_l2_error_fit"] <= s["rel_l2_error"] * (1 + 1e-9)
    # measured: 8-bit 1.76e-3 stored / 1.36e-4 fit, 16-bit 1.375e-4 / 1.361e-4, 16/8 9.4e-4 /
    # 1.41e-4
    rounding = [s["rel_l2_error"] - s["rel_l2_error_fit"] for s in (s16, sh, s8)]
    assert rounding[0] < 0.1 * rounding[1] and rounding[1] < rounding[2]


def test_exact_from_level_stores_upper_levels_exactly(baked, tmp_path):
    """``exact_from_level=1``: every level >= 1 group is its exact CP (errors at the 16-bit
    codes' rounding), level 0 fitted under the whole budget (its mean rank per byte is
    ``rank``, the exact groups take none of it), more bytes, and the setting is recorded."""
    nm = baked[0]
    kw = dict(rank=16, ndf_res=R, block=BLK, support=S, cell=16, converge=0.0, n_iter_max=300,
              tol=1e-7, progress=False, code_bits=16)
    s0 = bake(nm, tmp_path / "fit.npz", **kw)
    s1 = bake(nm, tmp_path / "exact.npz", exact_from_level=1, **kw)
    assert load(tmp_path / "exact.npz").header["settings"]["exact_from_level"] == 1
    e0, e1 = s0["rel_l2_error_per_level"], s1["rel_l2_error_per_level"]
    assert len(e1) >= 3
    g1 = load(tmp_path / "exact.npz")
    nb = R // BLK
    kept = np.zeros(g1.ranks.size)
    img, bi, bj = np.nonzero(g1.block_index >= 0)
    np.add.at(kept, g1.image_cell[img] * nb * nb + bi * nb + bj, 1)
    level0 = np.zeros(g1.ranks.size, bool)
    level0[g1.image_cell[:g1.pyramid.offsets[1]] * nb * nb + np.arange(nb * nb)[:, None]] = True
    unit = 2 * kept + 2 * BLK * 2 + 4  # bytes per rank: c codes, a and b codes, the scale
    fitted = level0 & (kept > 0)
    per_byte = unit[fitted] @ g1.ranks[fitted] / unit[fitted].sum()
    assert 0.9 * 16 <= per_byte <= 16 * (1 + 1e-9)
    # the budget was shared with the upper levels without the option: within 2x of that error
    assert e1[0] < 2 * e0[0]
    # exact up to a few 16-bit code steps (1.5e-5); the fit of level 1 errs 5-100x more (level
    # 2 holds few images: its rank-16 fit reaches the codes' rounding too)
    assert max(e1[1:]) < 5e-5 and e1[1] < e0[1] / 5
    assert s1["compressed_bytes"] > s0["compressed_bytes"]
    with pytest.raises(PrefilterError, match="exact_from_level"):
        bake(nm, tmp_path / "x.npz", exact_from_level=-1, **kw)


def test_exact_cell_one_image_per_group(baked, tmp_path):
    """``exact_cell=1``: the exact levels' groups hold one image each, so their ranks are at most
    ``B`` (the non-zero rows or columns of one block) instead of up to ``B^2``; the stored NDF is
    the same exact one (point queries agree with the per-cell exact bake to the codes' rounding);
    the setting is recorded and needs ``exact_from_level``."""
    nm = baked[0]
    kw = dict(rank=16, ndf_res=R, block=BLK, support=S, cell=16, converge=0.0, n_iter_max=300,
              tol=1e-7, progress=False, code_bits=16, exact_from_level=1)
    s1 = bake(nm, tmp_path / "cells.npz", **kw)
    s2 = bake(nm, tmp_path / "images.npz", exact_cell=1, **kw)
    g1, g2 = load(tmp_path / "cells.npz"), load(tmp_path / "images.npz")
    assert g2.header["settings"]["exact_cell"] == 1 and "exact_cell" not in g1.header["settings"]
    pyr = g2.pyramid
    upper = np.arange(pyr.offsets[1], pyr.n_images)
    # one cell (group) per image above level 0; level 0 keeps its cells of 4 x 4 centres
    assert len(np.unique(g2.image_cell[upper])) == upper.size
    assert len(np.unique(g1.image_cell[upper])) < upper.size
    nb = R // BLK
    ranks2 = g2.ranks.reshape(-1, nb * nb)
    cells_upper = np.unique(g2.image_cell[upper])
    assert 0 < ranks2[cells_upper].max() <= BLK
    assert g1.ranks.reshape(-1, nb * nb)[np.unique(g1.image_cell[upper])].max() > BLK
    e1, e2 = s1["rel_l2_error_per_level"], s2["rel_l2_error_per_level"]
    assert max(e2[1:]) < 5e-5 and max(e1[1:]) < 5e-5
    rng = np.random.default_rng(3)
    n = 4000
    center = rng.uniform(0, nm.shape[0], (n, 2))
    sigma_p = np.exp(rng.uniform(np.log(pyr.sigma(1)), np.log(pyr.sigma(pyr.n_levels - 1)), n))
    s = rng.uniform(-S, S, (n, 2))
    v1 = point(g1, center, sigma_p, s)
    v2 = point(g2, center, sigma_p, s)
    assert np.abs(v2 - v1).max() <= 1e-4 * np.abs(v1).max()
    with pytest.raises(PrefilterError, match="exact_cell"):
        bake(nm, tmp_path / "x.npz", **dict(kw, exact_from_level=None), exact_cell=1)
    with pytest.raises(PrefilterError, match="exact_cell"):
        bake(nm, tmp_path / "x.npz", exact_cell=0, **kw)


def test_16bit_codes_bake(baked, baked16):
    """``code_bits=16``: uint16 codes recorded in the settings, about the same ranks (the
    budget is per rank; only the 4 scale bytes per rank do not double, which moves a few
    groups), about twice the code bytes, and an error no larger than the 8-bit bake's."""
    _, _, s8, g8 = baked
    _, _, s16, g16 = baked16
    assert g16.header["settings"]["code_bits"] == 16 and "code_bits" not in g8.header["settings"]
    assert all(g16.codes[k].dtype == np.uint16 for k in ("a", "b", "c"))
    assert s16["mean_rank_per_byte"] == pytest.approx(s8["mean_rank_per_byte"], rel=0.05)
    for k in ("a", "c"):
        assert 1.8 <= s16["bytes"][k] / s8["bytes"][k] <= 2.2
    assert s16["rel_l2_error"] <= s8["rel_l2_error"] * 1.01


def test_16bit_codes_keep_uint16_prefix_sums(baked16):
    """16-bit ``a`` / ``b`` rows are scaled to code sums <= PREFIX_MAX (not to 65535 at their
    maximum), so the packed prefix sums are uint16; the codes still resolve each row to a step
    of at most 1 / (PREFIX_MAX - B / 2) of its sum."""
    from prefilter.glints.query import packed

    _, _, _, gm = baked16
    for k in ("a", "b"):
        sums = gm.codes[k].sum(axis=1, dtype=np.int64)
        assert sums.max() <= PREFIX_MAX and sums[sums > 0].min() >= PREFIX_MAX - BLK
    pa, pb = packed(gm)[:2]
    assert pa.dtype == pb.dtype == np.uint16


def test_factor_codes_by_maximum_unless_the_sum_overflows():
    """8-bit rows of 16 values keep 255 steps of their maximum (sums <= 4080: unchanged bytes);
    16-bit rows sum to at most PREFIX_MAX; a one-pixel row is capped too; zero rows stay zero."""
    rng = np.random.default_rng(3)
    f = rng.random((50, 16)) ** 6
    f /= f.sum(axis=1, keepdims=True)
    f[0] = 0.0
    f[1] = np.eye(16)[3]
    c8 = factor_codes(f, 255)
    np.testing.assert_array_equal(c8, np.rint(255 * f / np.maximum(f.max(1, keepdims=True),
                                                                     1e-300)))
    c16 = factor_codes(f, 65535)
    assert c16.sum(axis=1).max() <= PREFIX_MAX and np.all(c16[0] == 0)
    assert c16[1, 3] == PREFIX_MAX - 8 and c16.max() <= 65535
    err = np.abs(c16[2:] / c16[2:].sum(axis=1, keepdims=True) - f[2:])
    assert np.all(err <= (0.5 + 8 * f[2:]) / (PREFIX_MAX - 16))  # the bound of the test above


def test_16bit_files_with_uint32_prefix_sums_still_query(baked16, tmp_path):
    """Files written before the code-sum cap (each row 65535 steps of its maximum: sums past
    uint16) load with uint32 prefix sums and query the same NDF up to the codes' rounding."""
    from prefilter.fileio import read_npz, save_npz_atomic
    from prefilter.glints.query import packed

    _, path, _, gm = baked16
    data = {k: v for k, v in read_npz(path, "glints map").items() if k != "__meta__"}
    for k in ("a", "b"):
        f = data[k].astype(np.float64)
        m = np.maximum(f.max(axis=1, keepdims=True), 1.0)
        data[k] = np.rint(65535 * f / m).astype(np.uint16)
    old = tmp_path / "old16.npz"
    save_npz_atomic(old, format_name="prefilter-glints", format_version=3, **data)
    gm_old = load(old)
    assert packed(gm_old)[0].dtype == np.uint32
    rng = np.random.default_rng(8)
    c = rng.uniform(0, 32, (200, 2))
    sp = rng.uniform(0.5, 12, 200)
    s = rng.uniform(-S, S, (200, 2))
    want = point(gm, c, sp, s)
    np.testing.assert_allclose(point(gm_old, c, sp, s), want, rtol=1e-3, atol=1e-5 * want.max())


def test_bake_code_bits_errors(tmp_path):
    with pytest.raises(PrefilterError, match="code_bits: expected one of"):
        bake(sinusoid(16), tmp_path / "x.npz", code_bits=12, progress=False)
    with pytest.raises(PrefilterError, match="code_bits: expected one of"):
        encode([], 4)
    with pytest.raises(PrefilterError, match="c_bits: expected one of"):
        encode([], 16, 12)
    with pytest.raises(PrefilterError, match="c_bits: expected one of"):
        bake(sinusoid(16), tmp_path / "x.npz", c_bits=4, progress=False)


def test_loader_rejects_mixed_code_dtypes(baked16, tmp_path):
    from prefilter.fileio import read_npz, save_npz_atomic

    _, path, _, _ = baked16
    data = {k: v for k, v in read_npz(path, "glints map").items() if k != "__meta__"}
    data["a"] = data["a"].astype(np.uint8)
    bad = tmp_path / "mixed.npz"
    save_npz_atomic(bad, format_name="prefilter-glints", format_version=3, **data)
    with pytest.raises(TableFileError, match="b: expected a 2-D uint8 array, got uint16"):
        load(bad)


@pytest.mark.parametrize("bits", [8, 16, "16/8"])
@pytest.mark.parametrize("prefetch", [False, True])
def test_queries_are_the_stored_codes_evaluated_in_float64(baked, baked16, baked16c8, prefetch,
                                                          bits):
    """The kernels compute on the 8- or 16-bit codes: point values at pixel centres and range
    means of random fractional rectangles of single images == the float64 images rebuilt from
    the codes (1e-6 relative: the float32 per-component scale), with or without the prefetch
    stage."""
    from prefilter.glints import _qkernels as qk
    from prefilter.glints.query import kernel_args

    _, _, _, gm = {8: baked, 16: baked16, "16/8": baked16c8}[bits]
    rng = np.random.default_rng(7)
    images = rng.choice(gm.pyramid.n_images, 6, replace=False)
    ref = _images_from_codes(gm, images)
    arrs, lo, h = kernel_args(gm)
    n_pf = gm.pyramid.n_images if prefetch else 0
    s, _ = pixel_grid()
    n = R * R
    idx = np.repeat(images, n)[:, None].astype(np.int64)
    w = np.ones((idx.shape[0], 1))
    q = np.tile(s.reshape(-1, 2), (len(images), 1))
    got = np.empty(idx.shape[0])
    qk.point_kernel(*arrs, idx, w, q[:, 0].copy(), q[:, 1].copy(), lo, h, n_pf, got)
    np.testing.assert_allclose(got, ref.reshape(-1), rtol=1e-6, atol=1e-9 * ref.max())
    # ranges: exact integral of the piecewise-constant float64 image over the rectangle
    m = 300
    idx = rng.choice(images, m)[:, None].astype(np.int64)
    p0 = rng.uniform(-4, R, (m, 2))
    p1 = p0 + rng.uniform(0.2, 20, (m, 2))
    got = np.empty(m)
    qk.range_kernel(*arrs, idx, np.ones((m, 1)), lo + p0[:, 0] * h, lo + p0[:, 1] * h,
                    lo + p1[:, 0] * h, lo + p1[:, 1] * h, lo, h, n_pf, got)
    edges = np.arange(R + 1)
    for t in range(m):
        img = ref[list(images).index(idx[t, 0])]
        cover = [np.clip(np.minimum(edges[1:], p1[t, d]) - np.maximum(edges[:-1], p0[t, d]),
                         0, None) for d in (0, 1)]
        want = cover[1] @ img @ cover[0] / np.prod(p1[t] - p0[t])
        assert got[t] == pytest.approx(want, rel=1e-6, abs=1e-9 * ref.max())


def test_8bit_path_matches_the_float_path(baked):
    """The same map without its codes runs the kernels on the float32 arrays ``A``, ``Bp``, ``C``
    (what the loader decodes): point, bilinear, resampled and range queries agree up to the
    float32 rounding of the prefix sums (relative 1e-4 of the largest value; measured 1e-5 on a
    512^2 map)."""
    import dataclasses

    _, _, _, gm = baked
    gf = dataclasses.replace(gm, codes=None)
    rng = np.random.default_rng(8)
    n = 4000
    c = rng.uniform(0, 32, (n, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(40), n))
    s = rng.uniform(-S, S, (n, 2))
    lo = s - rng.uniform(0.001, 0.1, (n, 2))
    hi = s + rng.uniform(0.001, 0.1, (n, 2))
    for kw in ({}, {"bilinear": True}, {"interp": "resample"},
               {"interp": "resample", "bilinear": True}):
        a, b = point(gm, c, sp, s, **kw), point(gf, c, sp, s, **kw)
        assert np.count_nonzero(b) > n // 2
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4 * b.max())
    a, b = range_mean(gm, c, sp, lo, hi), range_mean(gf, c, sp, lo, hi)
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4 * b.max())


def _group_levels(gm):
    """Pyramid level ``(G,)`` of every CP group (-1: a cell without images) and its kept
    blocks ``(G,)`` (rows of ``C``)."""
    nb2 = (gm.resolution // gm.block) ** 2
    img_level = np.searchsorted(gm.pyramid.offsets, np.arange(gm.image_cell.size), "right") - 1
    cell_level = np.full(gm.ranks.size // nb2, -1)
    cell_level[gm.image_cell] = img_level
    return np.repeat(cell_level, nb2), np.diff(gm.codes["group_rows"])


@pytest.mark.slow
def test_bake_level_rank_budget_per_level(tmp_path):
    """``level_rank="level"``: every pyramid level's groups average at most ``rank`` per byte
    (bytes per rank: kept blocks + 2 block + 4) and the map's bytes are within the budget of a
    uniform rank; ``"uniform"``: every group at ``rank``; ``"global"`` (default) is uneven."""
    nm = sinusoid(32, ax=0.25, ay=0.2, px=16, py=8)
    kw = dict(rank=4, ndf_res=16, block=4, support=S, cell=8, converge=0.0, n_iter_max=20,
              progress=False, levels_dir=tmp_path / "levels")
    maps = {}
    for mode in ("global", "level", "uniform"):
        s = bake(nm, tmp_path / f"{mode}.npz", level_rank=mode, **kw)
        maps[mode] = (s, load(tmp_path / f"{mode}.npz"))
        assert maps[mode][1].header["settings"]["level_rank"] == mode
    gu = maps["uniform"][1]
    lv, kept = _group_levels(gu)
    live = kept > 0
    assert np.all(gu.ranks[live] == 4) and np.all(gu.ranks[~live] == 0)
    unit = kept + 2 * 4 + 4
    spread = {}
    for mode in ("global", "level"):
        s, gm = maps[mode]
        np.testing.assert_array_equal(_group_levels(gm)[1], kept)  # same blocks kept
        means = [unit[(lv == k) & live] @ gm.ranks[(lv == k) & live]
                 / unit[(lv == k) & live].sum() for k in range(gm.pyramid.n_levels)]
        spread[mode] = max(means) - min(means)
        assert unit @ gm.ranks <= 4 * unit.sum() + 1e-9
        assert s["compressed_bytes"] <= maps["uniform"][0]["compressed_bytes"]
        if mode == "level":
            assert max(means) <= 4 + 1e-9 and min(means) >= 2  # base = rank // 2
    assert gu.pyramid.n_levels >= 3 and spread["global"] > spread["level"]
    with pytest.raises(PrefilterError, match="level_rank"):
        bake(nm, tmp_path / "x.npz", level_rank="per-level", **kw)


def test_bake_error_weight_evens_the_groups_relative_errors(tmp_path):
    """``error_weight=1``: the allocation weighs each group's squared error by its squared norm's
    inverse (relative errors alike), so the same budget goes to the dim groups: the ranks
    spread less, the total error is higher (0 minimises it) and more of it sits in the largest
    groups (measured here: relative L2 3.0 -> 5.0 %, share of the top 10 % groups 0.31 ->
    0.61, largest rank 12 -> 8). Recorded in the settings only when not 0 (the default files'
    keys are unchanged); out-of-range values are an error."""
    from maps import gaussian_heightfield

    nm = gaussian_heightfield(32, corr=2, slope_std=0.2, seed=1)[0]
    kw = dict(rank=4, ndf_res=16, block=4, support=0.5, cell=8, converge=0.0, n_iter_max=20,
              progress=False, levels_dir=tmp_path / "levels")
    s0 = bake(nm, tmp_path / "w0.npz", **kw)
    s1 = bake(nm, tmp_path / "w1.npz", error_weight=1.0, **kw)
    g0, g1 = load(tmp_path / "w0.npz"), load(tmp_path / "w1.npz")
    assert "error_weight" not in g0.header["settings"]
    assert g1.header["settings"]["error_weight"] == 1.0
    assert abs(s1["compressed_bytes"] / s0["compressed_bytes"] - 1.0) < 0.01
    assert s1["mean_rank_per_byte"] <= 4 + 1e-9
    assert s1["rel_l2_error"] > 1.2 * s0["rel_l2_error"]
    assert s1["err2_share_top10pct_groups"] > 1.5 * s0["err2_share_top10pct_groups"]
    assert g1.ranks.max() < g0.ranks.max() and np.std(g1.ranks) < np.std(g0.ranks)
    for bad in (-0.5, 2.5, float("nan"), True, "1"):
        with pytest.raises(PrefilterError, match="error_weight"):
            bake(nm, tmp_path / "x.npz", error_weight=bad, **kw)


def test_float_arrays_are_decoded_lazily(baked):
    """A loaded version-3 map holds only the codes: queries and ``block_means`` leave ``A``,
    ``Bp``, ``C`` undecoded; on access they equal the eager decoding of the codes, and
    ``block_means`` from the codes equals the sums of ``C``'s rows."""
    import dataclasses

    _, out, _, _ = baked
    gm = load(out)
    assert all(gm.__dict__[f"_{k}"] is None for k in ("A", "Bp", "C"))
    point(gm, [[3.0, 5.0]], [2.0], [[0.01, 0.02]])
    range_mean(gm, [[3.0, 5.0]], [2.0], [[-0.1, -0.1]], [[0.1, 0.1]])
    img = np.arange(gm.pyramid.n_images)
    means = block_means(gm, img)
    assert all(gm.__dict__[f"_{k}"] is None for k in ("A", "Bp", "C"))
    A, Bp, C = decode(**gm.codes, width=gm.rank)
    for name, eager in (("A", A), ("Bp", Bp), ("C", C)):
        lazy = getattr(gm, name)
        assert lazy.dtype == eager.dtype and lazy.shape == eager.shape
        np.testing.assert_array_equal(lazy, eager)
    assert getattr(gm, "C") is gm.C  # decoded once
    gf = dataclasses.replace(gm, codes=None)
    np.testing.assert_allclose(means, block_means(gf, img), rtol=1e-6, atol=1e-12)
    assert np.count_nonzero(means) > means.size // 4
    assert "images" in repr(load(out))


def test_cli_bake_level_rank(tmp_path):
    from click.testing import CliRunner

    from prefilter.glints.commands import bake_glints

    np.save(tmp_path / "n.npy", sinusoid(16, px=16, py=8))
    args = [str(tmp_path / "n.npy"), "--rank", "4", "--ndf-res", "16", "--block", "8",
            "--cell", "8", "--iters", "10", "--quiet"]
    res = CliRunner().invoke(bake_glints, args + ["-o", str(tmp_path / "u.npz"),
                                                  "--level-rank", "uniform"])
    assert res.exit_code == 0, res.output
    gm = load(tmp_path / "u.npz")
    assert (np.asarray(gm.ranks) == 4).all()
    bad = CliRunner().invoke(bake_glints, args + ["-o", str(tmp_path / "b.npz"),
                                                  "--level-rank", "per-texel"])
    assert bad.exit_code != 0 and "level-rank" in bad.output


def _multi_case(gm, rng, n=300, k=5, interp="resample"):
    """Footprints over all pyramid levels with their blends (some taps zeroed) and ``k``
    rectangles each: small ones, ones crossing block borders, ones partly or wholly outside the
    support (``[-S, S]^2``)."""
    from prefilter.glints.query import weights

    c = rng.uniform(0, 32, (n, 2))
    sp = np.exp(rng.uniform(np.log(0.5), np.log(40), n))
    idx, w, _ = weights(gm, c, sp, interp=interp)
    w = np.where(rng.random(w.shape) < 0.2, 0.0, w)
    ctr = rng.uniform(-1.3 * S, 1.3 * S, (n, 1, 2)) + rng.normal(0, 0.05, (n, k, 2))
    half = np.exp(rng.uniform(np.log(0.002), np.log(0.3), (n, k, 2)))
    return idx, w, ctr - half, ctr + half


@pytest.mark.parametrize("interp,bits", [("resample", 8), ("trilinear", 8), ("resample", "16/8"),
                                         ("resample", 16)])
def test_range_multi_equals_range_weighted_per_rectangle(request, interp, bits):
    """One blend and K rectangles per footprint == :func:`range_weighted` of each rectangle:
    rtol 1e-5 on the code maps (8-bit ``c``: float32 sums of uint16 prefix sums, the 16/8
    render default included; measured <= 3e-7; 16-bit ``c``: float64), 1e-6 on the float maps
    (float64; measured <= 4e-7, the former kernel's rounding: against the float64 images
    rebuilt from the same float32 prefix sums it is off by up to 5e-8, range_multi by 2e-14)."""
    import dataclasses

    from prefilter.glints import query as gq

    _, _, _, gm0 = request.getfixturevalue({8: "baked", "16/8": "baked16c8", 16: "baked16"}[bits])
    B = gm0.block
    rng = np.random.default_rng(11)
    # blocks missing from some images (dropped by the bake where an image's block is empty)
    bi = gm0.block_index.copy()
    bi[rng.random(bi.shape) < 0.2] = -1
    gm = dataclasses.replace(gm0, block_index=bi)
    idx, w, lo, hi = _multi_case(gm, rng, interp=interp)
    n, k = lo.shape[:2]
    # rectangles crossing block borders and outside the support are both covered
    px_lo, px_hi = (lo + S) / (2 * S / R), (hi + S) / (2 * S / R)
    assert np.mean(np.floor(px_lo / B) != np.floor(px_hi / B)) > 0.3
    assert np.mean((px_lo < 0) | (px_hi > R)) > 0.1 and np.any((px_hi < 0) | (px_lo > R))
    for m, rtol in ((gm, 1e-5), (dataclasses.replace(gm, codes=None), 1e-6)):
        want = gq.range_weighted(m, np.repeat(idx, k, 0), np.repeat(w, k, 0),
                                 lo.reshape(-1, 2), hi.reshape(-1, 2)).reshape(n, k)
        assert np.count_nonzero(want) > want.size // 3
        got = gq.range_multi(m, idx, w, lo, hi)
        np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * 1e-3 * want.max())
        assert np.all(got[want == 0] == 0)
        act = rng.random((n, k)) < 0.7
        np.testing.assert_array_equal(gq.range_multi(m, idx, w, lo, hi, act),
                                      np.where(act, got, 0.0))
        # serial and parallel kernels alike, up to the float32 sums' rounding: they are separate
        # compilations and fastmath lets LLVM reassociate those sums differently (seen once in a
        # full test run: 1.3e-7 relative on the 8-bit map; not reproduced alone)
        big = np.repeat(np.arange(n), 120 // k * 300 // n + 1)
        got_p = gq.range_multi(m, idx[big], w[big], lo[big], hi[big])
        assert got_p.size >= gq.SERIAL_BELOW
        np.testing.assert_allclose(got_p, got[big], rtol=1e-6, atol=0)


def test_range_multi_input_errors(baked):
    from prefilter.glints.query import range_multi

    _, _, _, gm = baked
    idx = np.zeros((2, 3), np.int64)
    w = np.ones((2, 3))
    lo = np.zeros((2, 4, 2))
    with pytest.raises(PrefilterError, match="s_max > s_min"):
        range_multi(gm, idx, w, lo, lo)
    with pytest.raises(PrefilterError, match=r"s_min, s_max: expected shapes \(N, K, 2\)"):
        range_multi(gm, idx, w, lo[0], lo[0] + 1)
    with pytest.raises(PrefilterError, match="idx, w: expected"):
        range_multi(gm, idx, w[:, :2], lo, lo + 1)
    with pytest.raises(PrefilterError, match="idx: expected image indices"):
        range_multi(gm, idx - 1, w, lo, lo + 1)
    with pytest.raises(PrefilterError, match="active: expected a bool array"):
        range_multi(gm, idx, w, lo, lo + 1, np.ones((2, 3), bool))
    assert range_multi(gm, idx[:0], w[:0], lo[:0], lo[:0] + 1).shape == (0, 4)


def test_cli_bake_is_the_render_bake(tmp_path, monkeypatch):
    """``prefilter bake glints`` without -o writes the render cache's file: the glints render
    method (baked_surface) loads it instead of baking, with the same settings."""
    from click.testing import CliRunner

    from prefilter.glints import render as grender
    from prefilter.glints.bake import BAKE_SETTINGS, bake_settings, cache_path
    from prefilter.glints.commands import bake_glints

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "cache"))
    nm = sinusoid(16, px=16, py=8)
    np.save(tmp_path / "n.npy", nm)
    small = dict(rank=4, ndf_res=16, block=8, n_iter_max=10)
    res = CliRunner().invoke(bake_glints, [str(tmp_path / "n.npy"), "--rank", "4", "--ndf-res",
                                           "16", "--block", "8", "--iters", "10", "--quiet"])
    assert res.exit_code == 0, res.output
    path = cache_path(nm, bake_settings(nm.shape, small))
    assert path.exists() and str(path) in res.output
    st = load(path).header["settings"]
    for k, v in dict(BAKE_SETTINGS, **small).items():
        if k != "intrinsic_roughness":
            assert st[k] == v, k

    def found(normal_map, out, **kwargs):
        assert out == path and out.exists(), "baked again"
        return False

    monkeypatch.setattr(grender, "bake_if_missing", found)
    surf = grender.baked_surface(nm, settings=small)
    assert surf.gm.header["settings"] == st
