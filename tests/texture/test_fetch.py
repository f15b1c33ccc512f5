"""The compiled texel fetches of packed mip levels against a NumPy twin."""

import numpy as np

from prefilter.texture import MipChain
from prefilter.texture.fetch import CLAMP_UV, CLAMP_V, pack_levels, trilinear


def _bilinear_twin(tex, uv):
    """Periodic bilinear lookup of ``tex (H, W, C)`` at ``uv (N, 2)`` in NumPy."""
    h, w = tex.shape[:2]
    x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i0, j0 = np.mod(y0.astype(np.int64), h), np.mod(x0.astype(np.int64), w)
    i1, j1 = np.mod(i0 + 1, h), np.mod(j0 + 1, w)
    top = tex[i0, j0] * (1 - fx) + tex[i0, j1] * fx
    bottom = tex[i1, j0] * (1 - fx) + tex[i1, j1] * fx
    return top * (1 - fy) + bottom * fy


def test_periodic_trilinear_equals_numpy_twin():
    rng = np.random.default_rng(2)
    chain = MipChain(rng.random((32, 64, 3)))  # non-square: levels of unequal aspect
    uv = rng.uniform(-2.0, 3.0, (5000, 2))
    lod = rng.uniform(-1.0, chain.n_levels + 1.0, 5000)
    lod[:50] = np.floor(lod[:50])  # whole levels, the top one included
    lc = np.clip(lod, 0.0, chain.n_levels - 1)
    l0 = np.minimum(np.floor(lc).astype(int), chain.n_levels - 2)
    t = (lc - l0)[:, None]
    want = np.empty((5000, 3))
    for level in np.unique(l0):
        m = l0 == level
        want[m] = (_bilinear_twin(chain.levels[level], uv[m]) * (1 - t[m])
                   + _bilinear_twin(chain.levels[level + 1], uv[m]) * t[m])
    np.testing.assert_allclose(trilinear(pack_levels(chain.levels), uv, lod), want, rtol=0,
                               atol=1e-14)
    np.testing.assert_allclose(chain.lookup(uv, lod), want, rtol=0, atol=1e-14)


def test_clamped_columns_and_rows():
    a = np.arange(2 * 4 * 1, dtype=float).reshape(2, 4, 1)  # rows 0 1 2 3 / 4 5 6 7
    packed = pack_levels([a])
    # beyond the edge texels' centres, on any side: that texel, not a wrapped neighbour
    uv = [[0.0, 0.0], [-3.0, 0.25], [1.0, 0.0], [1.0, 1.0], [0.0, 7.0], [0.5, 0.5]]
    np.testing.assert_allclose(trilinear(packed, uv, 0.0, clamp=CLAMP_UV)[:, 0],
                               [0.0, 0.0, 3.0, 7.0, 4.0, 3.5])


def test_clamped_rows_and_packing():
    a = np.arange(2 * 4 * 1, dtype=float).reshape(2, 4, 1)  # rows 0 1 2 3 / 4 5 6 7
    data, offsets, heights, widths = pack_levels([a, a[:1, :2]])
    assert data.shape == (10, 1) and list(offsets) == [0, 8]
    assert list(heights) == [2, 1] and list(widths) == [4, 2]
    packed = (data, offsets, heights, widths)
    # beyond the first / last row centre: clamped to that row, not wrapped to the other one
    top = trilinear(packed, [[0.125, 0.0], [0.125, 1.0]], 0.0, clamp=CLAMP_V)[:, 0]
    np.testing.assert_allclose(top, [0.0, 4.0])
    # u wraps: halfway between the last and the first column of row 0
    np.testing.assert_allclose(trilinear(packed, [[1.0, 0.25]], 0.0, clamp=CLAMP_V)[:, 0], [1.5])
    # lod 0.5 blends the two levels equally; level 1 (texels 0 1) at u = 0.125 is a quarter
    # texel left of texel 0's centre: 3/4 of texel 0 and, wrapping, 1/4 of texel 1
    got = trilinear(packed, [[0.125, 0.25]], 0.5, clamp=CLAMP_V)[0, 0]
    assert got == 0.5 * 0.0 + 0.5 * 0.25
