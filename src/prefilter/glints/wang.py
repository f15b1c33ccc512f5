"""Wang tiles for glinty normal maps: synthesis, implicit tiling, P-NDFs across tiles (sec. 5.5).

**Tiles.** 16 tiles of ``T x T`` texels, 2 colours per edge direction (Cohen et al. 2003). Each
colour of the horizontal edges is a ``T x T`` source patch ``H_c`` of the input (random periodic
offset), each colour of the vertical edges a patch ``V_c``. A tile with colours ``(n, e, s, w)`` is
made of four triangles cut by its diagonals: the north triangle is the lower half of ``H_n``
(tile row ``y`` = patch row ``y + T/2``), the south one the upper half of ``H_s``, west/east
the right/left halves of ``V_w``/``V_e``. Two tiles sharing an edge colour therefore continue the
same patch across that edge: edges match exactly. **Seams** are inside the tiles, along the
diagonals: projected normals are cross-faded linearly over ``band`` texels (weights
``clip(1 + (m_r - max_r m_r) / band, 0, 1)`` normalised, with ``m_r`` the distance-to-centre
margin towards edge ``r``), then renormalised; only the ``band``-texel squares at the tile
corners, where two diagonal seams meet the edge, are not continuous across tiles.

**Implicit tiling** (Lagae and Dutre 2005, as modified by the paper): grid vertex ``(i, j)`` hashes
to two bits, the colours of the edge to its right (horizontal) and below it (vertical); tile
``(i, j)`` has ``n = right(i, j)``, ``s = right(i, j + 1)``, ``w = below(i, j)``,
``e = below(i + 1, j)``, index ``n + 2 s + 4 w + 8 e``. Only the 16 tiles and a seed are stored,
whatever the synthesised area.

**Direct P-NDFs across tiles.** :func:`pndf_implicit` / :func:`pndf_image_implicit`: the direct
P-NDF of the texels under the footprint, the tiles under its truncation window (plus a 2-texel
margin for the Jacobians) looked up by hashing and assembled locally; :func:`pndf_explicit` uses a
stored index map of a finite area (the paper's Fig. 14 comparison).

Per-tile footprint pyramids over these tiles (``TiledNDF``: bake, compression, queries,
sampling, file format) are in :mod:`prefilter.glints.wang_ndf`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from prefilter.jit import njit_serial
from prefilter.validation import as_float_array, as_positive_int, as_rng
from prefilter.errors import PrefilterError
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, SIGMA_H, TRUNCATION, as_normal_map,
                                   as_sigma_p, pndf, pndf_image)


@dataclass(frozen=True)
class WangTiles:
    """16 tiles ``(16, T, T, 3)`` indexed by ``n + 2 s + 4 w + 8 e`` and the hashing seed."""

    tiles: np.ndarray
    seed: int

    @property
    def size(self) -> int:
        return int(self.tiles.shape[1])

    @property
    def nbytes(self) -> int:
        return int(self.tiles.nbytes)


def synthesize(normal_map, tile: int = 32, band: float = 4.0, rng=0) -> WangTiles:
    """Build the 16 Wang tiles of ``tile`` texels from a periodic input normal map (see module
    docstring for the seam method)."""
    nm = as_normal_map(normal_map)
    T = as_positive_int(tile, "tile", lo=4)
    if T % 2:
        raise PrefilterError(f"tile: expected an even tile size, got {T}")
    if not (0.0 < float(band) <= T / 2):
        raise PrefilterError(f"band: expected a seam width in (0, {T / 2}], got {band}")
    gen = as_rng(rng)
    Hh, W = nm.shape[:2]
    r = np.arange(T)

    def patch():
        oy, ox = gen.integers(0, Hh), gen.integers(0, W)
        return nm[(oy + r)[:, None] % Hh, (ox + r)[None, :] % W]

    Hp = [patch(), patch()]
    Vp = [patch(), patch()]
    y = r[:, None] + 0.5 - T / 2
    x = r[None, :] + 0.5 - T / 2
    marg = np.stack(np.broadcast_arrays(-y, x, y, -x))  # n, e, s, w
    wts = np.clip(1.0 + (marg - marg.max(axis=0)) / float(band), 0.0, 1.0)
    wts /= wts.sum(axis=0)
    h2 = T // 2
    tiles = np.empty((16, T, T, 3))
    for idx in range(16):
        n, s, w, e = edge_colours(idx)
        srcs = [np.roll(Hp[n], -h2, axis=0), np.roll(Vp[e], h2, axis=1),
                np.roll(Hp[s], h2, axis=0), np.roll(Vp[w], -h2, axis=1)]
        sxy = sum(wt[..., None] * src[..., :2] for wt, src in zip(wts, srcs))
        z = np.sqrt(np.maximum(1.0 - np.sum(sxy * sxy, -1), 1e-6))
        t = np.concatenate([sxy, z[..., None]], -1)
        tiles[idx] = t / np.linalg.norm(t, axis=-1, keepdims=True)
    return WangTiles(tiles, int(gen.integers(0, 2**31)))


_H1, _H2, _H3 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), \
    np.uint64(0x165667B19E3779F9)
_H4, _S29, _S32, _ONE = np.uint64(0xBF58476D1CE4E5B9), np.uint64(29), np.uint64(32), np.uint64(1)


@njit_serial
def hash_bits(i, j, seed):  # pragma: no cover - compiled
    """Two pseudo-random bits per grid vertex ``(i, j)`` (a 64-bit integer mix of its
    coordinates): the colours of its right and lower edges."""
    h = (np.uint64(i) * _H1) ^ (np.uint64(j) * _H2) ^ (np.uint64(seed) * _H3)
    h ^= h >> _S29
    h *= _H4
    h ^= h >> _S32
    return np.int64(h & _ONE), np.int64((h >> _ONE) & _ONE)


@njit_serial
def edge_type(n, s, w, e):  # pragma: no cover - compiled
    """Tile index ``n + 2 s + 4 w + 8 e`` of the edge colours (0 or 1) north, south, west, east
    (:func:`edge_colours` inverts it; on the implicit tiling they are the right-edge bits of
    the tile's upper-left grid vertex and of the vertex below it, and the lower-edge bits of
    that vertex and of the one to its right, :func:`hash_bits`)."""
    return n + 2 * s + 4 * w + 8 * e


@njit_serial
def implicit_type(i, j, seed):  # pragma: no cover - compiled
    """Tile index of the implicit tiling at tile ``(i, j)`` from the colours of its edges."""
    r_ij, b_ij = hash_bits(i, j, seed)
    return edge_type(r_ij, hash_bits(i, j + 1, seed)[0], b_ij, hash_bits(i + 1, j, seed)[1])


@njit_serial
def _tile_index_kernel(i, j, seed, out):  # pragma: no cover - compiled
    for k in range(out.shape[0]):
        out[k] = implicit_type(i[k], j[k], seed)


def tile_index(wt: WangTiles, i, j) -> np.ndarray:
    """Implicit tile index at tile coordinates ``(i, j)`` (column, row), any integers."""
    i, j = np.broadcast_arrays(np.asarray(i, np.int64), np.asarray(j, np.int64))
    out = np.empty(i.shape, np.int64)
    _tile_index_kernel(np.ascontiguousarray(i).reshape(-1), np.ascontiguousarray(j).reshape(-1),
                       int(wt.seed), out.reshape(-1))
    return out


def index_map(wt: WangTiles, ny: int, nx: int, i0: int = 0, j0: int = 0) -> np.ndarray:
    """Explicit ``(ny, nx)`` index map of tiles ``(i0 .. i0 + nx - 1, j0 .. j0 + ny - 1)``."""
    J, I = np.meshgrid(np.arange(ny) + j0, np.arange(nx) + i0, indexing="ij")
    return tile_index(wt, I, J)


def periodic_index_map(ny: int, nx: int, rng=0) -> np.ndarray:
    """An ``(ny, nx)`` index map whose periodic repetition is a valid Wang tiling (every edge
    colour matches across the wrap too): random colours per grid vertex of the ``ny x nx``
    torus, tiles indexed as the implicit tiling's. ``index_map`` of a finite block wraps onto
    mismatched edges."""
    ny = as_positive_int(ny, "ny")
    nx = as_positive_int(nx, "nx")
    gen = as_rng(rng)
    right = gen.integers(0, 2, (ny, nx))
    below = gen.integers(0, 2, (ny, nx))
    return right + 2 * np.roll(right, -1, axis=0) + 4 * below + 8 * np.roll(below, -1, axis=1)


def assemble(wt: WangTiles, index: np.ndarray) -> np.ndarray:
    """Normal map ``(ny T, nx T, 3)`` of an index map ``(ny, nx)``."""
    idx = np.asarray(index)
    t = wt.tiles[idx]  # (ny, nx, T, T, 3)
    ny, nx, T = idx.shape[0], idx.shape[1], wt.size
    return t.transpose(0, 2, 1, 3, 4).reshape(ny * T, nx * T, 3)


def is_valid_tiling(index) -> bool:
    """Whether the periodic repetition of the tile index map ``index (ny, nx)`` is a valid Wang
    tiling: every tile's north colour is the south colour of the tile above, its west colour
    the east colour of the tile to its left, across the wrap too (as :func:`periodic_index_map`
    makes them; a block of the implicit tiling, :func:`index_map`, generally is not)."""
    t = np.asarray(index)
    n, s, w, e = edge_colours(t)
    return bool(np.array_equal(n, np.roll(s, 1, axis=0))
                and np.array_equal(w, np.roll(e, 1, axis=1)))


def edge_colours(idx):
    """Edge colours ``(n, s, w, e)`` (each 0 or 1, shaped like ``idx``) of tile indices
    ``n + 2 s + 4 w + 8 e``."""
    idx = np.asarray(idx)
    return idx & 1, (idx >> 1) & 1, (idx >> 2) & 1, (idx >> 3) & 1


def tile_window(wt: WangTiles, c, sp: float) -> tuple[int, int, int, int]:
    """First tile ``(i0, j0)`` and tile counts ``(nx, ny)`` of a local map holding every texel
    (and its Jacobian's neighbours) under the truncation window of footprint ``c (2,)``,
    ``sp``."""
    T = wt.size
    rad = TRUNCATION * math.sqrt(float(sp) ** 2 + SIGMA_H**2) + 2.0
    i0, i1 = math.floor((c[0] - rad) / T), math.floor((c[0] + rad) / T)
    j0, j1 = math.floor((c[1] - rad) / T), math.floor((c[1] + rad) / T)
    # one extra tile each side keeps the periodic wrap of the local map out of the window
    return i0 - 1, j0 - 1, i1 - i0 + 3, j1 - j0 + 3


def pndf_implicit(wt: WangTiles, center, sigma_p, s,
                  intrinsic_roughness: float = DEFAULT_ROUGHNESS) -> np.ndarray:
    """Direct P-NDF over the implicitly tiled plane: one footprint ``center (2,)`` (texels, any
    position), ``sigma_p`` scalar, ``s (..., 2)``; the tiles under the footprint are looked up by
    hashing and assembled locally."""
    c = as_center(center)
    sp = as_one_sigma_p(sigma_p)
    i0, j0, nx, ny = tile_window(wt, c, sp)
    local = assemble(wt, index_map(wt, ny, nx, i0, j0))
    T = wt.size
    return pndf(local, c - np.array([i0 * T, j0 * T]), sp, s, intrinsic_roughness)


def pndf_explicit(wt: WangTiles, index: np.ndarray, center, sigma_p, s,
                  intrinsic_roughness: float = DEFAULT_ROUGHNESS) -> np.ndarray:
    """Direct P-NDF on the normal map assembled from a stored index map (tiles ``(0, 0)`` at
    the origin; footprints must stay inside it, the assembled map is periodic)."""
    return pndf(assemble(wt, index), center, sigma_p, s, intrinsic_roughness)


def pndf_image_implicit(wt: WangTiles, center, sigma_p, resolution: int = 64,
                        support: float = 0.5,
                        intrinsic_roughness: float = DEFAULT_ROUGHNESS) -> np.ndarray:
    """Direct NDF image ``(R, R)`` (``pndf.pndf_image``) of one footprint ``center (2,)``,
    ``sigma_p`` over the implicitly tiled plane (tiles assembled locally, as
    :func:`pndf_implicit`)."""
    c = as_center(center)
    sp = as_one_sigma_p(sigma_p)
    i0, j0, nx, ny = tile_window(wt, c, sp)
    local = assemble(wt, index_map(wt, ny, nx, i0, j0))
    T = wt.size
    return pndf_image(local, c - np.array([i0 * T, j0 * T]), sp, resolution, support,
                      intrinsic_roughness)


def as_one_sigma_p(sigma_p) -> float:
    """One validated footprint std (a scalar)."""
    sp = as_sigma_p(sigma_p)
    if sp.shape != ():
        raise PrefilterError(f"sigma_p: expected one footprint std, got shape {sp.shape}")
    return float(sp)


def as_center(center) -> np.ndarray:
    """One validated footprint centre ``(2,)`` in texels."""
    c = as_float_array(center, "center")
    if c.shape != (2,):
        raise PrefilterError(f"center: expected one footprint centre (x, y), got shape {c.shape}")
    return c
