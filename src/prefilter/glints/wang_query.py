"""Compressed per-tile Wang pyramids in the layout of the ``glints`` query kernels.

:class:`TilePack` holds the CP factors of every (level, tile, angular block) group of a
compressed :class:`prefilter.glints.wang_ndf.TiledNDF` as the kernels of
:mod:`prefilter.glints._qkernels` read them (their module docstring; glints paper eq. 5): the
factors ``Fa``, ``Fb`` and their prefix sums ``Pa``, ``Pb`` rank-innermost per group, the code
rows ``cq`` of each group consecutive, the per-component scale ``wsc`` and the group records
``meta (G, 4)`` (rank, first component, first code row, row stride). A ``wang_store`` version-2
file is packed from its integer codes without decoding them (uint8 or uint16 ``Fa``, ``Fb``,
``cq``; integer prefix sums; ``wsc = c_scale / Q^3``): the packed pyramids take about the file's
bytes in memory. Other compressed pyramids are packed from their float32 triples (``wsc = 1``).

Images: level ``l``'s image of tile ``t`` and crop centre ``(b, a)`` is
``img = offs[l] + (t n_l + b) n_l + a``; ``bidx[bi, bj, img]`` (images innermost: a query's
taps along a row are adjacent) is its code row within group
``goff[l] + t nb^2 + bi nb + bj``, -1 when the row is all zero (not stored).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from prefilter.glints._qkernels import _block_tap, _flush_slots
from prefilter.glints.store import code_levels
from prefilter.jit import njit_serial


@dataclass(frozen=True, eq=False)
class TilePack:
    """Packed CP pyramids of the 16 Wang tiles (module docstring for the layout)."""

    Pa: np.ndarray  # (M, B + 1) prefix sums of the row factors, rank-innermost per group
    Pb: np.ndarray
    cq: np.ndarray  # (K rank,) code rows, group-major
    wsc: np.ndarray  # (M,) float32 scale per component
    Fa: np.ndarray  # (M B,) row factors, rank-innermost per group
    Fb: np.ndarray
    bidx: np.ndarray  # (nb, nb, n_img) int16 row within the group, -1: zero row
    meta: np.ndarray  # (G, 4) int64 rank, first component, first code row, row stride
    offs: np.ndarray  # (L + 1,) first image of each level
    goff: np.ndarray  # (L + 1,) first group of each level
    crops: np.ndarray  # (L,) centres per axis of each level
    block: int

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, k).nbytes for k in
                       ("Pa", "Pb", "cq", "wsc", "Fa", "Fb", "bidx", "meta", "offs", "goff",
                        "crops")))

    @property
    def C(self) -> tuple:
        """The ``C`` tuple of the ``_qkernels`` helpers: ``(cq, wsc, Fa, Fb)``."""
        return self.cq, self.wsc, self.Fa, self.Fb


def _prefix(f: np.ndarray, dtype) -> np.ndarray:
    """Prefix sums ``(G, B + 1, rank)`` over the factor entries of ``f (G, rank, B)``."""
    G, r, B = f.shape
    out = np.zeros((G, B + 1, r), dtype)
    np.cumsum(f.transpose(0, 2, 1), axis=1, dtype=dtype, out=out[:, 1:])
    return out


def _pack_level(kept, a, b, c, scale, prefix_dtype):
    """One level: ``kept (16, n, n, nb^2)`` bool (the stored rows), the live groups' factors
    ``a``, ``b (G_live, rank, B)`` in ``(t, g)`` order, the kept rows ``c (K, rank)`` in
    ``(t, b, a, g)`` order and the live groups' scales ``(G_live, rank)``. Returns the level's
    parts: ``Fa``, ``Fb (G_live rank B,)``, ``Pa``, ``Pb (G_live rank, B + 1)``, ``cq`` rows
    group-major, ``wsc``, ``bidx (16 n n, nb^2)``, ``live (16 nb^2,)`` and rows per live
    group."""
    n_t, n, _, nb2 = kept.shape
    rank, B = a.shape[1], a.shape[2]
    live = kept.any(axis=(1, 2)).reshape(-1)  # (16 nb^2,) in (t, g) order
    # group of each kept row, and the rows reordered group-major (stable: (b, a) order inside)
    t_, b_, a_, g_ = np.nonzero(kept)
    gid = t_ * nb2 + g_
    order = np.argsort(gid, kind="stable")
    cq = np.ascontiguousarray(c[order])
    # row within the group: running count of the group's kept rows in (b, a) order
    kg = kept.transpose(0, 3, 1, 2).reshape(n_t * nb2, n * n)
    within = np.cumsum(kg, axis=1) - 1
    bidx = np.where(kg, within, -1).astype(np.int16)  # (16 nb^2, n n)
    bidx = bidx.reshape(n_t, nb2, n * n).transpose(0, 2, 1).reshape(n_t * n * n, nb2)
    rows = kg.sum(axis=1)[live]
    fa = np.ascontiguousarray(a.transpose(0, 2, 1)).reshape(-1)  # (G, B, rank) flat
    fb = np.ascontiguousarray(b.transpose(0, 2, 1)).reshape(-1)
    pa = _prefix(a, prefix_dtype).reshape(-1, B + 1) if a.size else np.zeros((0, B + 1),
                                                                             prefix_dtype)
    pb = _prefix(b, prefix_dtype).reshape(-1, B + 1) if b.size else np.zeros((0, B + 1),
                                                                             prefix_dtype)
    # Pa rows of group g: rank-innermost block of (B + 1) rank values (flat m (B + 1) + i r + rr)
    pa = pa.reshape(-1, (B + 1) * rank).reshape(-1, B + 1)
    pb = pb.reshape(-1, (B + 1) * rank).reshape(-1, B + 1)
    return fa, fb, pa, pb, cq, np.asarray(scale, np.float32).reshape(-1), bidx, live, rows


def _assemble(parts, crops, rank, B, n_groups) -> TilePack:
    L = len(parts)
    offs = np.zeros(L + 1, np.int64)
    goff = np.zeros(L + 1, np.int64)
    metas, m0, c0 = [], 0, 0
    for lv, (_, _, _, _, cq, _, bidx, live, rows) in enumerate(parts):
        offs[lv + 1] = offs[lv] + bidx.shape[0]
        goff[lv + 1] = goff[lv] + live.size
        meta = np.zeros((live.size, 4), np.int64)
        nl = int(live.sum())
        comp = m0 + rank * np.arange(nl)
        start = c0 + rank * np.concatenate([[0], np.cumsum(rows)[:-1]]).astype(np.int64)
        meta[live] = np.stack([np.full(nl, rank), comp, start, np.full(nl, rank)], -1)
        metas.append(meta)
        m0 += rank * nl
        c0 += cq.size
    cat = np.concatenate
    nb = int(round(n_groups ** 0.5))
    bidx = cat([p[6] for p in parts]).T.reshape(nb, nb, -1)
    return TilePack(Pa=cat([p[2] for p in parts]), Pb=cat([p[3] for p in parts]),
                    cq=cat([p[4].reshape(-1) for p in parts]),
                    wsc=cat([p[5] for p in parts]).astype(np.float32),
                    Fa=cat([p[0] for p in parts]), Fb=cat([p[1] for p in parts]),
                    bidx=np.ascontiguousarray(bidx), meta=cat(metas), offs=offs, goff=goff,
                    crops=np.asarray(crops, np.int64), block=int(B))


def empty_pack(n_levels: int, like: TilePack | None = None) -> TilePack:
    """A :class:`TilePack` of no group: the kernels' placeholder for absent pyramids
    (uncompressed ones; a bake without vertex or coarse pyramids). ``like``: with its arrays'
    dtypes (the kernel compiled for ``like`` serves both), else float32."""
    z = np.zeros(n_levels + 1, np.int64)

    def none(name, width=None):
        dt = np.float32 if like is None else getattr(like, name).dtype
        return np.zeros(0 if width is None else (0, width), dt)

    B1 = 2 if like is None else like.Pa.shape[1]
    return TilePack(Pa=none("Pa", B1), Pb=none("Pb", B1), cq=none("cq"), wsc=none("wsc"),
                    Fa=none("Fa"), Fb=none("Fb"), bidx=np.zeros((1, 1, 0), np.int16),
                    meta=np.zeros((1, 4), np.int64), offs=z, goff=z.copy(),
                    crops=np.zeros(n_levels, np.int64), block=0 if like is None else like.block)


class DecodedLevels(Sequence):
    """The levels of a :class:`TilePack` packed from integer codes as float32 CP triples ``(A,
    Bf (16, nb^2, rank, B), C (16, n, n, nb^2, rank))`` (:class:`prefilter.glints.wang_ndf.
    TiledNDF`; the values of :func:`prefilter.glints.wang_store.decode_level` up to float32
    rounding), each decoded on first access and kept: what the per-footprint NumPy paths read
    (the batched kernels read the pack)."""

    def __init__(self, pack: "TilePack"):
        self._pk = pack
        self._done: dict = {}

    def __len__(self) -> int:
        return int(self._pk.crops.shape[0])

    def __getitem__(self, lv):
        if isinstance(lv, slice):
            return [self[i] for i in range(*lv.indices(len(self)))]
        lv = range(len(self))[lv]
        if lv not in self._done:
            self._done[lv] = _decode(self._pk, lv)
        return self._done[lv]


def _decode(pk: "TilePack", lv: int):
    nb = pk.bidx.shape[0]
    nb2 = nb * nb
    n = int(pk.crops[lv])
    B = pk.block
    meta = pk.meta[pk.goff[lv]:pk.goff[lv + 1]]
    live = meta[:, 0] > 0
    rank = int(pk.meta[:, 0].max())
    Q = float(code_levels(pk.cq.dtype))
    A = np.zeros((16 * nb2, rank, B), np.float32)
    Bf = np.zeros_like(A)
    ent = meta[live, 1][:, None] * B + np.arange(B * rank)[None]  # (G_live, B rank)
    A[live] = (pk.Fa[ent].reshape(-1, B, rank).transpose(0, 2, 1) / Q).astype(np.float32)
    Bf[live] = (pk.Fb[ent].reshape(-1, B, rank).transpose(0, 2, 1) / Q).astype(np.float32)
    kidx = pk.bidx[:, :, pk.offs[lv]:pk.offs[lv + 1]].reshape(nb2, 16, n, n)
    kidx = kidx.transpose(1, 2, 3, 0)  # (16, n, n, nb^2)
    C = np.zeros((16, n, n, nb2, rank), np.float32)
    t, b, a, g = np.nonzero(kidx >= 0)
    grp = meta[t * nb2 + g]
    r = np.arange(rank)[None]
    rows = pk.cq[(grp[:, 2] + kidx[t, b, a, g].astype(np.int64) * grp[:, 3])[:, None] + r]
    C[t, b, a, g] = (rows * (pk.wsc[grp[:, 1][:, None] + r].astype(np.float64) * Q * Q)
                     ).astype(np.float32)
    return A.reshape(16, nb2, rank, B), Bf.reshape(16, nb2, rank, B), C


def pack_codes(levels, crops, n_groups: int) -> TilePack:
    """:class:`TilePack` of a version-2 file's levels: ``levels[l]`` the dict of arrays
    ``mask``, ``a``, ``b``, ``c``, ``c_scale`` (:func:`prefilter.glints.wang_store.encode_level`),
    ``crops[l]`` its centres per axis, ``n_groups = nb^2``. The codes are kept as stored:
    a pixel is ``c_scale / Q^3 sum_r a b c`` (``Q`` the codes' steps)."""
    parts = []
    rank = B = 0
    for lv, d in enumerate(levels):
        n = int(crops[lv])
        a, b, c = d["a"], d["b"], d["c"]
        rank, B = a.shape[1], a.shape[2]
        kept = np.unpackbits(d["mask"], count=16 * n * n * n_groups).astype(bool)
        kept = kept.reshape(16, n, n, n_groups)
        Q = float(code_levels(c.dtype))
        pdt = np.uint16 if c.dtype == np.uint8 else np.uint32
        scale = np.asarray(d["c_scale"], np.float64) / Q**3
        parts.append(_pack_level(kept, a, b, c, scale, pdt))
    return _assemble(parts, crops, rank, B, n_groups)


def pack_float(images) -> TilePack:
    """:class:`TilePack` of CP triples ``(A, Bf (16, nb^2, rank, B), C (16, n, n, nb^2, rank))``
    float32 per level (:class:`prefilter.glints.wang_ndf.TiledNDF`), ``wsc = 1``; all-zero rows
    are not stored."""
    parts, crops = [], []
    rank = B = nb2 = 0
    for A, Bf, C in images:
        n_t, nb2, rank, B = A.shape
        n = C.shape[1]
        crops.append(n)
        kept = C.max(axis=-1) > 0  # (16, n, n, nb^2)
        live = kept.any(axis=(1, 2))  # (16, nb^2)
        parts.append(_pack_level(kept, np.asarray(A, np.float32)[live],
                                 np.asarray(Bf, np.float32)[live],
                                 np.asarray(C, np.float32)[kept],
                                 np.ones((int(live.sum()), rank)), np.float32))
    return _assemble(parts, crops, rank, B, nb2)


@njit_serial
def gauss_row(c, x0, x1, tot2):  # pragma: no cover - compiled
    """``exp(-(c - x - 0.5)^2 / (2 tot2))`` for texels ``x = x0 .. x1`` ``(x1 - x0 + 1,)``: the
    footprint weights along one axis (Yan et al. 2016), by the recurrence of consecutive ratios
    (two products a texel), an exact ``exp`` every 32 texels (relative error ~1e-14)."""
    n = x1 - x0 + 1
    out = np.empty(max(n, 0))
    inv = 1.0 / (2.0 * tot2)
    q = math.exp(-2.0 * inv)
    g = 0.0
    r = 0.0
    for k in range(n):
        if k % 32 == 0:
            d = c - (x0 + k) - 0.5
            g = math.exp(-d * d * inv)
            r = math.exp((2.0 * d - 1.0) * inv)  # g(k + 1) / g(k)
        else:
            g *= r
            r *= q
        out[k] = g
    return out


@njit_serial
def segment_moments(g, x0, T, P, out):  # pragma: no cover - compiled
    """``out[a, d] = sum of g[x - x0] P[d, x - (i0 + a) T]`` over the texels ``x`` of tile
    ``i0 + a = x0 // T + a``: the footprint weights' in-tile moments along one axis (``g`` as
    :func:`gauss_row`, ``P (3, T)`` the polynomials of
    :func:`prefilter.glints.wang_ndf.moment_basis`, ``P[0] = 1``: ``d = 0`` the plain sums)."""
    i0 = x0 // T
    x1 = x0 + g.shape[0] - 1
    p1 = P[1]
    p2 = P[2]
    for a in range(out.shape[0]):
        base = (i0 + a) * T
        lo = max(x0, base)
        n = min(x1, base + T - 1) + 1 - lo
        gs = g[lo - x0:lo - x0 + n]
        q1 = p1[lo - base:lo - base + n]
        q2 = p2[lo - base:lo - base + n]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(n):
            s0 += gs[k]
            s1 += gs[k] * q1[k]
            s2 += gs[k] * q2[k]
        out[a, 0] = s0
        out[a, 1] = s1
        out[a, 2] = s2


@njit_serial
def tile_taps(cy, cx, T, st, r, half, km, n, jlo, jhi, ilo, ihi):  # pragma: no cover
    """Resampling taps per tile row ``jlo..jhi`` and column ``ilo..ihi`` of a footprint centred
    at ``(cx, cy)`` (texels) on level grids of stride ``st`` (crop centres ``km .. km + n - 1``
    of each tile, tile-relative: the grids of neighbouring tiles differ when the stride does not
    divide ``T``): taps within ``half`` strides, Gaussian weights of std ``r`` normalised over
    all of the tile's taps, kept inside the crop. Returns ``wyt (rows, n)``, ``wxt (cols, n)``
    (weight per crop index) and the crop index ranges ``kyl, kyh``, ``kxl, kxh``."""
    wyt = np.zeros((jhi - jlo + 1, n))
    wxt = np.zeros((ihi - ilo + 1, n))
    kyl = np.empty(jhi - jlo + 1, np.int64)
    kyh = np.empty(jhi - jlo + 1, np.int64)
    kxl = np.empty(ihi - ilo + 1, np.int64)
    kxh = np.empty(ihi - ilo + 1, np.int64)
    for a in range(2):
        cc = cy if a == 0 else cx
        t0 = jlo if a == 0 else ilo
        wt = wyt if a == 0 else wxt
        klo = kyl if a == 0 else kxl
        khi = kyh if a == 0 else kxh
        for e in range(wt.shape[0]):
            rel = cc - (t0 + e) * T
            gg = (rel - 0.5) / st
            ka, kb = int(math.ceil(gg - half)), int(math.floor(gg + half))
            # exp(-((k st + 0.5 - rel) / r)^2 / 2) for k = ka .. kb
            g = gauss_row(gg + 0.5, ka, kb, (r / st) ** 2)
            nrm = 0.0
            for k in range(g.shape[0]):
                nrm += g[k]
            klo[e] = max(ka, km) - km
            khi[e] = min(kb, km + n - 1) - km
            for k in range(klo[e], khi[e] + 1):
                wt[e, k] = g[k + km - ka] / nrm
    return wyt, wxt, kyl, kyh, kxl, kxh


@njit_serial
def tile_codes(cq, row_idx, meta, off, goff, n, gblk, types, jt, it, wyt, wxt, kyl, kyh, kxl,
               kxh, cw, gs, slot_of):  # pragma: no cover - compiled
    """Sum the taps' code rows of one NDF block (``row_idx``: ``bidx[bi, bj]``, ``gblk =
    (bi nb + bj, nb^2)``) per CP group into ``cw[slot]`` (in ``cw``'s dtype; tiles of one type
    share their group, so at most 16 slots), group of each slot in ``gs``; returns the slots
    used. Arguments as :func:`pack_point`."""
    ns = 0
    for t in range(16):
        slot_of[t] = -1
    for jj in range(wyt.shape[0]):
        if kyl[jj] > kyh[jj]:
            continue
        for ii in range(wxt.shape[0]):
            if kxl[ii] > kxh[ii]:
                continue
            t = types[jt + jj, it + ii]
            g = goff + t * gblk[1] + gblk[0]
            nr = meta[g, 0]
            if nr == 0:
                continue
            sl = slot_of[t]
            if sl < 0:
                sl = ns
                slot_of[t] = sl
                gs[sl] = g
                for rr in range(nr):
                    cw[sl, rr] = 0.0
                ns += 1
            cb, strd = meta[g, 2], meta[g, 3]
            base = off + t * n * n
            for ky in range(kyl[jj], kyh[jj] + 1):
                wy = wyt[jj, ky]
                rimg = base + ky * n
                for kx in range(kxl[ii], kxh[ii] + 1):
                    k = row_idx[rimg + kx]
                    if k < 0:
                        continue
                    wt = np.float32(wy * wxt[ii, kx])
                    e = cb + k * strd
                    cr = cq[e:e + nr]
                    for rr in range(nr):
                        cw[sl, rr] += wt * np.float32(cr[rr])
    return ns


@njit_serial
def type_weights(types, jt, it, wyt, wxt, kyl, kyh, kxl, kxh, n, W, box):  # pragma: no cover
    """The resampling taps of the tiles under a footprint summed per tile type (tiles of one
    type share their images): ``W[t] (n, n)`` the summed tap weights of the type-``t`` tiles
    (tile ``(jj, ii)`` of type ``types[jt + jj, it + ii]``, taps as :func:`pack_point`'s),
    written inside ``box[t] = (ky0, ky1, kx0, kx1)`` only (``ky0 > ky1``: no tile of the type).
    One pass over the taps for all the NDF blocks a query reads."""
    for t in range(16):
        box[t, 0], box[t, 1], box[t, 2], box[t, 3] = n, -1, n, -1
    for jj in range(wyt.shape[0]):
        if kyl[jj] > kyh[jj]:
            continue
        for ii in range(wxt.shape[0]):
            if kxl[ii] > kxh[ii]:
                continue
            t = types[jt + jj, it + ii]
            box[t, 0] = min(box[t, 0], kyl[jj])
            box[t, 1] = max(box[t, 1], kyh[jj])
            box[t, 2] = min(box[t, 2], kxl[ii])
            box[t, 3] = max(box[t, 3], kxh[ii])
    for t in range(16):
        for ky in range(box[t, 0], box[t, 1] + 1):
            for kx in range(box[t, 2], box[t, 3] + 1):
                W[t, ky, kx] = 0.0
    for jj in range(wyt.shape[0]):
        if kyl[jj] > kyh[jj]:
            continue
        for ii in range(wxt.shape[0]):
            t = types[jt + jj, it + ii]
            for ky in range(kyl[jj], kyh[jj] + 1):
                wy = wyt[jj, ky]
                for kx in range(kxl[ii], kxh[ii] + 1):
                    W[t, ky, kx] += wy * wxt[ii, kx]


@njit_serial
def type_codes(cq, row_idx, meta, off, goff, n, gblk, W, box, cw, gs):  # pragma: no cover
    """Sum the code rows of one NDF block (``row_idx``: ``bidx[bi, bj]``, ``gblk = (bi nb +
    bj, nb^2)``) weighted by :func:`type_weights`' ``W``, ``box`` per CP group (one per tile
    type) into ``cw[slot]`` (in ``cw``'s dtype), group of each slot in ``gs``; returns the
    slots used. ``off``, ``goff``: the level's first image and group."""
    ns = 0
    for t in range(16):
        if box[t, 0] > box[t, 1]:
            continue
        g = goff + t * gblk[1] + gblk[0]
        nr = meta[g, 0]
        if nr == 0:
            continue
        sl = ns
        gs[sl] = g
        for rr in range(nr):
            cw[sl, rr] = 0.0
        ns += 1
        cb, strd = meta[g, 2], meta[g, 3]
        base = off + t * n * n
        for ky in range(box[t, 0], box[t, 1] + 1):
            rimg = base + ky * n
            for kx in range(box[t, 2], box[t, 3] + 1):
                k = row_idx[rimg + kx]
                if k < 0:
                    continue
                wt = np.float32(W[t, ky, kx])
                if wt == 0.0:
                    continue
                e = cb + k * strd
                cr = cq[e:e + nr]
                for rr in range(nr):
                    cw[sl, rr] += wt * np.float32(cr[rr])
    return ns


@njit_serial
def pack_point(Fa, Fb, wsc, cq, bidx, meta, off, goff, n, B, types, jt, it, wyt, wxt, kyl, kyh,
               kxl, kxh, i0, u0, u1, j0, v0, v1, cw, gs, slot_of):  # pragma: no cover
    """One footprint's sum over the tiles under it of their resampling taps at level ``m``
    (images from ``off``, groups from ``goff``, ``n`` centres per axis), at the NDF pixel taps
    ``(i0, u0, u1)`` (rows) and ``(j0, v0, v1)`` (columns) of :func:`prefilter.glints.
    _qkernels.pixel_taps`. Tile ``(jj, ii)`` of the window is of type ``types[jt + jj, it +
    ii]``; its taps are the crop rows ``kyl[jj]..kyh[jj]`` weighted ``wyt[jj]`` and columns
    ``kxl[ii]..kxh[ii]`` weighted ``wxt[ii]``. Per NDF block, the taps' code rows are summed
    per CP group (all tiles of one type share their group: at most 16 slots of ``cw``,
    float32), then one factor product per group (``_qkernels._flush_slots``, as
    ``resample_point_kernel``; glints paper eq. 5). Over more than 16 tiles the taps are
    summed per tile type first (:func:`type_weights`, :func:`type_codes`: fewer code rows read
    when types repeat); over fewer, tile by tile (:func:`tile_codes`: no extra pass, and a
    point query reads one NDF block but at block borders)."""
    nb = bidx.shape[0]
    nb2 = nb * nb
    rows = 0
    for jj in range(wyt.shape[0]):
        rows += kyl[jj] <= kyh[jj]
    cols = 0
    for ii in range(wxt.shape[0]):
        cols += kxl[ii] <= kxh[ii]
    by_type = rows * cols > 16
    W = np.empty((16, n, n) if by_type else (0, 0, 0))
    box = np.empty((16, 4), np.int64)
    if by_type:
        type_weights(types, jt, it, wyt, wxt, kyl, kyh, kxl, kxh, n, W, box)
    acc = 0.0
    for di in range(2):
        bi, ia, wi, wa1 = _block_tap(i0, u0, u1, di, B)
        if bi < 0:
            continue
        for dj in range(2):
            bj, ja, wj, wb1 = _block_tap(j0, v0, v1, dj, B)
            if bj < 0:
                continue
            if by_type:
                ns = type_codes(cq, bidx[bi, bj], meta, off, goff, n, (bi * nb + bj, nb2), W,
                                box, cw, gs)
            else:
                ns = tile_codes(cq, bidx[bi, bj], meta, off, goff, n, (bi * nb + bj, nb2),
                                types, jt, it, wyt, wxt, kyl, kyh, kxl, kxh, cw, gs, slot_of)
            acc += _flush_slots(Fa, Fb, wsc, meta, B, gs, cw, ns, wi, wa1, wj, wb1, ia, ja)
    return acc
