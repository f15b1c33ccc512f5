"""Wang tiles (glints paper sec. 5.5): edge-colour consistency of the implicit tiling, seamless
tile edges, implicit == explicit (stored index map) P-NDFs (the paper's Fig. 14), constant
storage."""

import numpy as np
import pytest
from maps import sinusoid

from prefilter.errors import PrefilterError
from prefilter.glints.wang import (assemble, index_map, pndf_explicit, pndf_implicit, synthesize,
                                   tile_index)

T = 16


@pytest.fixture(scope="module")
def wt():
    return synthesize(sinusoid(64, ax=0.25, ay=0.2, px=16, py=8), tile=T, band=3.0, rng=4)


def test_edge_colours_match(wt):
    idx = index_map(wt, 40, 50, -20, 7)
    n, s, w, e = idx & 1, (idx >> 1) & 1, (idx >> 2) & 1, (idx >> 3) & 1
    np.testing.assert_array_equal(s[:-1], n[1:])  # tile below shares the horizontal edge
    np.testing.assert_array_equal(e[:, :-1], w[:, 1:])  # tile to the right, the vertical one
    counts = np.bincount(idx.ravel(), minlength=16)
    assert np.all(counts > 0.5 * idx.size / 16)  # all 16 tiles, roughly uniformly


def test_tile_edges_are_seamless(wt):
    """Across tile edges (away from the corner squares) neighbouring texels are as close as
    neighbours of the smooth input; across a wrong patch they would jump."""
    big = assemble(wt, index_map(wt, 6, 6))
    s = big[..., :2]
    mid = slice(4, T - 4)
    d_edges = []
    for k in range(1, 6):
        rows = s[k * T - 1:k * T + 1].reshape(2, 6, T, 2)[:, :, mid]
        cols = s[:, k * T - 1:k * T + 1].reshape(6, T, 2, 2)[:, mid]
        d_edges += [np.abs(rows[1] - rows[0]).max(), np.abs(cols[:, :, 1] - cols[:, :, 0]).max()]
    src = sinusoid(64, ax=0.25, ay=0.2, px=16, py=8)[..., :2]
    d_src = max(np.abs(np.diff(src, axis=0)).max(), np.abs(np.diff(src, axis=1)).max())
    assert max(d_edges) <= d_src + 1e-12
    # the synthesised map differs from any single patch: tiles really mix four sources
    assert np.abs(np.diff(s, axis=0)).max() > d_src


@pytest.mark.parametrize("c, sp", [((37.3, 52.1), 3.0), ((48.0, 40.0), 9.0), ((60.2, 71.4), 6.0)])
def test_implicit_equals_explicit(wt, c, sp):
    idx = index_map(wt, 8, 8)
    g = np.linspace(-0.35, 0.35, 41)
    s = np.stack(np.meshgrid(g, g), -1)
    a = pndf_implicit(wt, c, sp, s, 0.01)
    b = pndf_explicit(wt, idx, c, sp, s, 0.01)
    assert b.max() > 1.0
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * b.max())


def test_constant_storage(wt):
    before = wt.nbytes
    g = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 9), np.linspace(-0.3, 0.3, 9)), -1)
    for c in ((10.0, 10.0), (1e6 + 0.3, -3e5), (-7e7, 2e7)):
        v = pndf_implicit(wt, c, 5.0, g, 0.02)
        assert np.all(np.isfinite(v)) and v.sum() > 0
    assert wt.nbytes == before == 16 * T * T * 3 * 8
    assert tile_index(wt, 10**9, -(10**9)).shape == ()


def test_validation():
    nm = sinusoid(32)
    with pytest.raises(PrefilterError, match="tile"):
        synthesize(nm, tile=15)
    with pytest.raises(PrefilterError, match="band"):
        synthesize(nm, tile=16, band=20)
