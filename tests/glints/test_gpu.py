"""The GPU export of a baked glints map (``prefilter.glints.gpu``): texture layout within WebGL2's
limits (refused, naming the limit, beyond them), and the three code variants reproduce the
query kernels' values (float32 to rounding, float16 and 8-bit within their quantisation)."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.glints.gpu import (CODE_FORMATS, WEBGL2_LIMITS, export_gpu, glsl_source,
                                  texture_shape)
from prefilter.glints.query import packed


def test_texture_shape_fills_rows_then_layers():
    assert texture_shape(10, "x") == (10, 1, 1)
    assert texture_shape(2048 * 3 + 1, "x") == (2048, 4, 1)
    assert texture_shape(2048 * 2048 + 1, "x") == (2048, 2048, 2)
    assert texture_shape(5000, "x", {"MAX_TEXTURE_SIZE": 4096}) == (4096, 2, 1)


def test_texture_beyond_the_limits_is_refused_naming_them():
    n = 2048 * 2048 * 256 + 1
    with pytest.raises(PrefilterError, match="fa.*MAX_ARRAY_TEXTURE_LAYERS = 256"):
        texture_shape(n, "fa")
    # the same count fits a browser with more layers
    assert texture_shape(n, "fa", {"MAX_ARRAY_TEXTURE_LAYERS": 2048})[2] == 257
    with pytest.raises(PrefilterError, match="int32"):
        texture_shape(2**31, "c", {"MAX_ARRAY_TEXTURE_LAYERS": 10**6})
    assert WEBGL2_LIMITS["MAX_TEXTURE_SIZE"] == 2048


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    from prefilter.glints.bake import bake
    from prefilter.glints.store import load
    from prefilter.texture import normal_map

    nm = normal_map("flakes", size=32, seed=2)
    out = tmp_path_factory.mktemp("gpu") / "m.npz"
    bake(nm, out, rank=8, ndf_res=64, block=16, stride0=4, cell=16, code_bits=16, c_bits=8,
         progress=False)
    return nm, load(out)


def test_export_variants_reproduce_the_kernel_values(small):
    nm, gm = small
    _, _, (cq, wsc, fa, fb), meta, _, _ = packed(gm)
    B = gm.block
    # every kept block's pixel (i, j) = sum_r wsc c fa fb; compare each variant's product
    k = np.flatnonzero(gm.block_index.ravel() >= 0)
    rng = np.random.default_rng(0)
    pick = rng.choice(k, min(200, k.size), replace=False)
    nb = gm.resolution // B
    img, blk = pick // (nb * nb), pick % (nb * nb)
    g = gm.image_cell[img] * nb * nb + blk
    kc = meta[g, 2] + gm.block_index.ravel()[pick] * meta[g, 3]
    i, j = rng.integers(0, B, pick.size), rng.integers(0, B, pick.size)

    def values(fa_, fb_, c_, w_, kc_):
        out = np.zeros(pick.size)
        for n in range(pick.size):
            nr, m = meta[g[n], 0], meta[g[n], 1]
            r = np.arange(nr)
            out[n] = np.sum(w_[m + r] * c_[kc_[n] + r] * fa_[m * B + i[n] * nr + r]
                            * fb_[m * B + j[n] * nr + r])
        return out

    ref = values(fa.ravel().astype(float), fb.ravel().astype(float), cq.astype(float), wsc, kc)
    assert np.sum(ref > 0) > 20
    tol = {"f32": 1e-6, "f16": 2e-3, "u8": 0.05}
    for codes in CODE_FORMATS:
        e = export_gpu(gm, nm, codes=codes)
        t = {name: v["data"].astype(np.float64) for name, v in e["textures"].items()}
        scale = 255.0 if codes == "u8" else 1.0
        # the code rows in RGBA texels: index holds each block's first texel
        kc_gpu = 4 * e["textures"]["index"]["data"][pick].astype(np.int64)
        got = values(t["fa"] / scale, t["fb"] / scale, t["c"] / scale, t["w"], kc_gpu)
        err = np.abs(got - ref) / max(ref.max(), 1e-30)
        assert err.max() < tol[codes], (codes, err.max())
        assert e["params"]["textures"]["fa"][0] <= WEBGL2_LIMITS["MAX_TEXTURE_SIZE"]
        # prefix sums end at each component's total
        assert t["pa"].size >= gm.ranks.sum() * (B + 1)


def test_export_refuses_unknown_codes_and_small_limits(small):
    nm, gm = small
    with pytest.raises(PrefilterError, match="codes"):
        export_gpu(gm, codes="f8")
    with pytest.raises(PrefilterError, match="MAX_ARRAY_TEXTURE_LAYERS = 1"):
        export_gpu(gm, nm, limits={"MAX_TEXTURE_SIZE": 16, "MAX_ARRAY_TEXTURE_LAYERS": 1})


def test_glsl_source_has_the_python_constants():
    from prefilter.glints.pyramid import RESAMPLE_Q_MIN, RESAMPLE_TRUNCATION

    src = glsl_source()
    assert f"GLT_RESAMPLE_Q_MIN = {RESAMPLE_Q_MIN!r}" in src
    assert f"GLT_RESAMPLE_TRUNCATION = {RESAMPLE_TRUNCATION!r}" in src
    for fn in ("glPointQuery", "glRangeQuery", "glDirectNdf", "glintBrdfCos", "glVcavityG1"):
        assert fn in src
