"""The compiled texel fetches of packed mip levels against the array lookups."""

import numpy as np

from prefilter.texture import MipChain
from prefilter.texture.fetch import pack_levels, trilinear


def test_periodic_trilinear_equals_mipchain_lookup():
    rng = np.random.default_rng(2)
    chain = MipChain(rng.random((32, 64, 3)))  # non-square: levels of unequal aspect
    uv = rng.uniform(-2.0, 3.0, (5000, 2))
    lod = rng.uniform(-1.0, chain.n_levels + 1.0, 5000)
    lod[:50] = np.floor(lod[:50])  # whole levels, the top one included
    np.testing.assert_allclose(trilinear(pack_levels(chain.levels), uv, lod),
                               chain.lookup(uv, lod), rtol=0, atol=1e-14)


def test_clamped_rows_and_packing():
    a = np.arange(2 * 4 * 1, dtype=float).reshape(2, 4, 1)  # rows 0 1 2 3 / 4 5 6 7
    data, offsets, heights, widths = pack_levels([a, a[:1, :2]])
    assert data.shape == (10, 1) and list(offsets) == [0, 8]
    assert list(heights) == [2, 1] and list(widths) == [4, 2]
    packed = (data, offsets, heights, widths)
    # beyond the first / last row centre: clamped to that row, not wrapped to the other one
    top = trilinear(packed, [[0.125, 0.0], [0.125, 1.0]], 0.0, clamp_v=True)[:, 0]
    np.testing.assert_allclose(top, [0.0, 4.0])
    # u wraps: halfway between the last and the first column of row 0
    np.testing.assert_allclose(trilinear(packed, [[1.0, 0.25]], 0.0, clamp_v=True)[:, 0], [1.5])
    # lod 0.5 blends the two levels equally; level 1 (texels 0 1) at u = 0.125 is a quarter
    # texel left of texel 0's centre: 3/4 of texel 0 and, wrapping, 1/4 of texel 1
    got = trilinear(packed, [[0.125, 0.25]], 0.5, clamp_v=True)[0, 0]
    assert got == 0.5 * 0.0 + 0.5 * 0.25
