"""On-disk format of per-tile Wang pyramids (``wang_store``): round trips (every query equal after
load, compressed and not), corrupt / truncated / wrong-version / inconsistent files (each a
TableFileError naming the file and the field), and the ``prefilter bake glints-wang`` CLI."""

import json

import numpy as np
import pytest
from maps import sinusoid

from prefilter._io import META_KEY
from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.wang import index_map, synthesize
from prefilter.glints.wang_ndf import (bake_tiles, compress_tiles, ndf, ndf_image, ndf_points,
                                       sample)
from prefilter.glints.wang_store import FORMAT, VERSION, load_tiles, save_tiles

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


def test_round_trip_compressed(wc, tmp_path):
    save_tiles(wc, tmp_path / "c.npz")
    back = load_tiles(tmp_path / "c.npz")
    assert back.block == 8 and back.cp_error == wc.cp_error and back.nbytes == wc.nbytes
    _same_queries(wc, back)
    header = json.loads(str(np.load(tmp_path / "c.npz")["header"]))
    assert header["format"] == FORMAT and header["version"] == VERSION
    assert header["settings"]["rank"] == 2 and header["tile"] == T
    assert header["arrays"]["C_0"]["shape"] == list(wc.images[0][2].shape)


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
    with pytest.raises(TableFileError, match=rf"v.npz: header.version: expected {VERSION}, got"):
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


def test_save_validation(wn, tmp_path):
    with pytest.raises(PrefilterError, match="wn: expected a TiledNDF"):
        save_tiles(wn.wang, tmp_path / "a.npz")
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
    assert summary["tiles"] == 16 and summary["stored_bytes"] == back.nbytes
    assert summary["file_bytes"] == out.stat().st_size
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
    from prefilter.glints.commands import bake_glints, bake_glints_wang

    shared = ("ndf_res", "block", "support", "roughness", "iters", "seed", "quiet")
    opts = {c.name: {p.name: p for p in c.params} for c in (bake_glints, bake_glints_wang)}
    want = {"glints": (128, 16, 0.5, 0.005, 50, 0, False),
            "glints-wang": (64, 8, 0.5, 0.005, 100, 0, False)}
    for name, defaults in want.items():
        assert tuple(opts[name][k].default for k in shared) == defaults
        assert opts[name]["quiet"].is_flag and opts[name]["block"].show_default
    assert opts["glints"]["seed"].help is None
    assert opts["glints-wang"]["seed"].help.startswith("Seeds the tile synthesis")
    order = [[p.name for p in c.params if p.name in shared]
             for c in (bake_glints, bake_glints_wang)]
    assert order == [list(shared), ["block", "ndf_res", *shared[2:]]]
