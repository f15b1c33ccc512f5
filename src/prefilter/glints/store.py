"""On-disk format of a baked glints map: one ``.npz`` with a JSON header, versioned.

In memory (:class:`GlintsMap`; ``G`` groups, ``R`` rank, ``B`` block size, ``nb = ndf_res / B``,
``N`` images):

* ``A``, ``Bp`` ``(G, R, B + 1)`` float32: 1D prefix sums of the row / column factors ``a_r``,
  ``b_r`` of each group (columns sum to 1, so each prefix sum runs from 0 to 1).
* ``C`` ``(K, R)`` float32: the third factors with the CP weights folded in, one row per kept block;
  the rows of a group are contiguous.
* ``block_index`` ``(N, nb, nb)`` int32: row of ``C`` of block ``[bi, bj]`` of each image,
  -1 = blank.
* ``image_cell`` ``(N,)`` int32: cell of each image (a group of images of one pyramid level); the
  group of block ``[bi, bj]`` of an image is ``image_cell * nb^2 + bi * nb + bj``.

On disk, version 3 (what :func:`save` writes with :func:`encode`'s arrays) stores per-group ranks
and 8-bit factors (the arrays above are decoded from them on first access, zero-padded to the
largest rank; the queries compute on the 8-bit codes and never decode them):

* ``ranks (G,)`` uint16: rank of each group (the bake allocates them under a storage budget; 0 for
  a group without kept blocks).
* ``a``, ``b`` ``(sum(ranks), B)`` uint8: each component's factor rounded to 255 steps of its
  maximum (columns renormalised to sum 1 at load, so no scale is stored); groups in order.
* ``c (sum_k ranks[group(k)],)`` uint8: the rows of ``C`` in row order, each with its group's rank
  of entries, in 255 steps of ``c_scale (sum(ranks),)`` float32 (the component's maximum over the
  group's rows).
* ``a``, ``b``, ``c`` may instead all be uint16 (65535 steps; ``bake(code_bits=16)``): the
  number of steps is the dtype's maximum (:func:`code_levels`); ``c`` may keep uint8 codes while
  ``a``, ``b`` are uint16 (``bake(code_bits=16, c_bits=8)``, the renderer's setting: the 8-bit
  rounding that matters is that of ``a``, ``b``). The encoder caps each ``a`` / ``b`` row's
  code sum at 65535 (:func:`factor_codes`; the loader's renormalisation makes the scale free),
  so the queries' prefix sums fit uint16; files without that cap load as they are (uint32
  prefix sums).
* ``block_mask (N, ceil(nb^2 / 8))`` uint8: packed bits, set for kept blocks (row-major
  ``[bi, bj]``). The rows of ``C`` are ordered by group, then by image, so ``block_index`` and the
  group offsets follow from the mask and ``image_cell`` (:func:`block_index_from_mask`).
* ``image_cell (N,)`` int32.

The 8-bit rounding adds 0.01 points of relative L2 error to a 5.47 % fit (sampled cells of the
512^2 gaussian map, rank 24; float16 added nothing measurable): see docs/glints.md. On the
render's much closer fits it dominates: the brushed 128^2 map's 0.235 % is 0.110 % with 16-bit
codes. Version 2
(float16 factors of one rank, ``c_scale`` per group and rank, ``group_rows``, an int32
``block_index``) and version 1 (float32 prefix sums ``A``, ``Bp``, ``C``) still load.

All factor values are non-negative, so every reconstructed NDF value and range mean is >= 0.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

from prefilter.fileio import (META_KEY, decode_json_object, read_npz, save_npz_atomic,
                          verify_npz)
from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.pyramid import Pyramid
from prefilter.jit import njit_serial

FORMAT = "prefilter-glints"
VERSION = 3
Q = 255  # levels of the 8-bit factors
#: bits of the stored factor codes :func:`encode` can write (uint8 or uint16 arrays)
CODE_BITS = (8, 16)
#: their array dtypes (shared with the Wang tiles file, :mod:`prefilter.glints.wang_store`)
CODE_DTYPES = {8: np.uint8, 16: np.uint16}


def code_levels(dtype) -> int:
    """Steps of a factor code array of ``dtype`` (uint8: 255, uint16: 65535)."""
    return int(np.iinfo(dtype).max)
ARRAYS = ("A", "Bp", "C", "block_index", "image_cell")  # in memory, and on disk in version 1
ARRAYS_V2 = ("a", "b", "c", "c_scale", "group_rows", "block_index", "image_cell")
ARRAYS_V3 = ("ranks", "a", "b", "c", "c_scale", "block_mask", "image_cell")


class _Decoded:
    """A float factor array of :class:`GlintsMap` (``A``, ``Bp`` or ``C``) decoded from the
    map's 8- or 16-bit ``codes`` on first access when it was given as None: the query kernels
    compute on the codes, so a loaded version-3 map holds only them (the float arrays of a 512^2
    map are ~340 MB). A required dataclass field (no default)."""

    def __set_name__(self, owner, name):
        self.name, self.key = name, "_" + name

    def __get__(self, obj, objtype=None):
        if obj is None:
            raise AttributeError(self.name)  # the dataclass sees no default
        value = obj.__dict__.get(self.key)
        if value is None and obj.__dict__.get("codes") is not None:
            value = obj.__dict__[self.key] = decode(**obj.codes, width=obj.rank,
                                                    which=self.name)[0]
        return value

    def __set__(self, obj, value):
        obj.__dict__[self.key] = value


@dataclass(repr=False)
class GlintsMap:
    """A compressed NDF pyramid (see the module docstring for the arrays). ``A``, ``Bp``, ``C``
    may be given as None when ``codes`` is set: each is then decoded on first access."""

    header: dict
    A: np.ndarray = _Decoded()
    Bp: np.ndarray = _Decoded()
    C: np.ndarray = _Decoded()
    block_index: np.ndarray
    image_cell: np.ndarray
    #: bytes of the arrays as stored on disk (set by :func:`encode` / :func:`load`)
    stored_bytes: int | None = None
    #: ``(G,)`` rank of each group (version 3; its components come first in ``A``, ``Bp``, ``C``,
    #: zeros after them up to ``rank``); None: every group uses all ``rank`` components
    ranks: np.ndarray | None = None
    #: version 3: the stored 8-bit arrays ``ranks``, ``a``, ``b``, ``c``, ``c_scale`` and
    #: ``group_rows (G + 1,)``, what the query kernels compute on (exact w.r.t. the stored
    #: values, a fraction of the memory traffic of ``A``, ``Bp``, ``C``); None: the kernels use
    #: the float arrays
    codes: dict | None = None

    @property
    def pyramid(self) -> Pyramid:
        p = self.header["pyramid"]
        return Pyramid(int(p["height"]), int(p["width"]), int(p["stride0"]), float(p["sigma0"]),
                       int(p["n_levels"]))

    @property
    def resolution(self) -> int:
        return int(self.header["ndf"]["resolution"])

    @property
    def support(self) -> float:
        return float(self.header["ndf"]["support"])

    @property
    def block(self) -> int:
        return int(self.header["ndf"]["block"])

    @property
    def rank(self) -> int:
        return int(self.header["ndf"]["rank"])

    @property
    def compressed_bytes(self) -> int:
        """Bytes stored on disk (the in-memory float32 prefix sums when not known)."""
        if self.stored_bytes is not None:
            return int(self.stored_bytes)
        return int(sum(getattr(self, k).nbytes for k in ARRAYS))

    def __repr__(self):  # without decoding the lazy float arrays
        n = self.block_index.shape[0] if self.block_index is not None else 0
        return f"GlintsMap({n} images, rank {self.header.get('ndf', {}).get('rank')})"


def encode_v2(a: np.ndarray, b: np.ndarray, c: np.ndarray, group_rows: np.ndarray) -> dict:
    """Version-2 arrays of float64 factors ``a``, ``b`` ``(G, R, B)`` (columns summing to 1 or
    zero) and ``c (K, R)`` whose rows ``group_rows[g]:group_rows[g + 1]`` belong to group ``g``."""
    G, R = a.shape[:2]
    rows = np.asarray(group_rows, dtype=np.int64)
    gmax = np.zeros((G, R))
    np.maximum.at(gmax, np.repeat(np.arange(G), np.diff(rows)), c)
    scale = np.where(gmax > 0, gmax, 1.0).astype(np.float32)
    per_row = np.repeat(scale, np.diff(rows), axis=0).astype(np.float64)
    c16 = np.divide(c, per_row, out=np.zeros_like(c, dtype=np.float64), where=per_row > 0)
    return dict(a=a.astype(np.float16), b=b.astype(np.float16), c=c16.astype(np.float16),
                c_scale=scale, group_rows=rows)


#: Largest code sum of an ``a`` / ``b`` row: the queries' integer prefix sums of the codes are
#: then exact in uint16 (:func:`prefilter.glints.query.packed`).
PREFIX_MAX = int(np.iinfo(np.uint16).max)


def factor_codes(f: np.ndarray, Q: int) -> np.ndarray:
    """Codes ``(R, B)`` float64 (integers in ``[0, Q]``) of non-negative factor rows ``f (R, B)``:
    ``Q`` steps of each row's maximum, unless the row's codes would then sum past
    :data:`PREFIX_MAX`; such rows (16-bit codes: all but one-pixel rows) are scaled to a sum of
    at most ``PREFIX_MAX`` instead, a step of ``1 / 65527`` of the row's sum for ``B = 16`` rather
    than ``1 / 65535`` of its maximum. Why: uint32 prefix sums made the environment's range
    queries ~1.1x slower than uint16 ones (benchmarks/bench_glints_codes.py: 100.5 vs 90.2 ms
    with 16-bit ``c``)."""
    f = np.asarray(f, np.float64)
    if not f.size:
        return np.zeros(f.shape)
    m = f.max(axis=1, keepdims=True)
    s = f.sum(axis=1, keepdims=True)
    by_max = np.divide(Q * f, m, out=np.zeros(f.shape), where=m > 0)
    # rounding adds at most 1/2 per entry: keep ceil(B / 2) steps of headroom
    cap = PREFIX_MAX - -(-f.shape[1] // 2)
    over = (Q * s > cap * m)[:, 0]
    by_max[over] = f[over] * (cap / s[over])
    return np.rint(by_max)


def encode(groups: list, code_bits: int = 8, c_bits: int | None = None) -> dict:
    """Version-3 factor arrays (``ranks``, ``a``, ``b``, ``c``, ``c_scale``) of groups given as
    ``(a (r_g, B), b (r_g, B), c (K_g, r_g))`` non-negative float factors (``a``, ``b`` rows
    summing to 1 or zero); concatenating the arrays of consecutive runs of groups gives those of
    the whole run. ``code_bits`` (8 or 16): ``a``, ``b`` as uint8 or uint16 codes; ``c_bits``:
    those of ``c`` (default ``code_bits``)."""
    c_bits = code_bits if c_bits is None else c_bits
    for name, bits in (("code_bits", code_bits), ("c_bits", c_bits)):
        if bits not in CODE_DTYPES:
            raise PrefilterError(f"{name}: expected one of {CODE_BITS}, got {bits!r}")
    dt, dc = CODE_DTYPES[code_bits], CODE_DTYPES[c_bits]
    Q, Qc = code_levels(dt), code_levels(dc)
    ranks, qa, qb, qc, sc = [], [], [], [], []
    for a, b, c in groups:
        ranks.append(a.shape[0])
        for f, out in ((a, qa), (b, qb)):
            out.append(factor_codes(f, Q))
        m = c.max(axis=0) if c.shape[0] else np.zeros(c.shape[1])
        qc.append(np.rint(np.divide(Qc * c, m, out=np.zeros(c.shape), where=m > 0)).ravel())
        sc.append(m)
    B = groups[0][0].shape[1] if groups else 0
    cat = (lambda xs, shape: np.concatenate(xs) if xs else np.zeros(shape))
    return dict(ranks=np.array(ranks, np.uint16), a=cat(qa, (0, B)).astype(dt),
                b=cat(qb, (0, B)).astype(dt), c=cat(qc, (0,)).astype(dc),
                c_scale=cat(sc, (0,)).astype(np.float32))


def decode(ranks, a, b, c, c_scale, group_rows, width: int | None = None,
           which: str | None = None) -> tuple[np.ndarray, ...]:
    """Float32 prefix sums ``A``, ``Bp`` ``(G, width, B + 1)`` and ``C (K, width)`` of version-3
    arrays, each group's components first and zeros after them (``width`` defaults to the
    largest rank); ``group_rows (G + 1,)``: first row of ``C`` of each group. ``which``
    (``"A"``, ``"Bp"`` or ``"C"``): only that array, as a 1-tuple."""
    ranks = np.asarray(ranks, np.int64)
    G = ranks.shape[0]
    W = int(ranks.max(initial=0)) if width is None else int(width)
    B = a.shape[1]
    off = np.concatenate([[0], np.cumsum(ranks)])
    comp_g = np.repeat(np.arange(G), ranks)
    comp_r = np.arange(off[-1]) - off[comp_g]
    out = {}
    for name, f in (("A", a), ("Bp", b)):
        if which in (None, name):
            out[name] = np.zeros((G, W, B + 1), np.float32)
            out[name][comp_g, comp_r] = _prefix(f)
    if which not in (None, "C"):
        return (out[which],)
    rows = np.asarray(group_rows, np.int64)
    K = int(rows[-1])
    row_g = np.repeat(np.arange(G), np.diff(rows))
    row_rank = ranks[row_g]
    row_off = np.concatenate([[0], np.cumsum(row_rank)])
    e_row = np.repeat(np.arange(K), row_rank)
    e_col = np.arange(row_off[-1]) - row_off[e_row]
    C = np.zeros((K, W), np.float32)
    C[e_row, e_col] = (c.astype(np.float32) * np.float32(1.0 / code_levels(c.dtype))
                       * c_scale[off[row_g[e_row]] + e_col])
    return (C,) if which == "C" else (out["A"], out["Bp"], C)


@njit_serial
def _rank_major_kernel(f, ranks, out):  # pragma: no cover - compiled
    n = f.shape[1]
    m = 0
    for g in range(ranks.shape[0]):
        r = ranks[g]
        base = m * n
        for rr in range(r):
            for i in range(n):
                out[base + i * r + rr] = f[m + rr, i]
        m += r


def rank_major(f: np.ndarray, ranks) -> np.ndarray:
    """Factors ``f (M, n)`` of groups of ``ranks`` (consecutive components) reordered so that
    group ``g``'s block of ``r_g n`` values is ``[i, r]``: flat index ``m_g n + i r_g + r``
    (``M = sum ranks``); the copy is the only allocation (an index array of the same shape in
    int64 took 4-8x the factors' bytes while a render packed its maps)."""
    f = np.ascontiguousarray(f)
    M, n = f.shape
    out = np.empty(M * n, f.dtype)
    _rank_major_kernel(f, np.asarray(ranks, np.int64), out)
    return out.reshape(M, n)


def pack_mask(kept: np.ndarray) -> np.ndarray:
    """``block_mask (N, ceil(nb^2 / 8))`` uint8 of the kept-block flags ``(N, nb, nb)``."""
    return np.packbits(np.asarray(kept, bool).reshape(kept.shape[0], -1), axis=1)


def block_index_from_mask(block_mask: np.ndarray, image_cell: np.ndarray, nb: int,
                          n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """``block_index (N, nb, nb)`` int32 and ``group_rows (n_groups + 1,)`` int64 of a packed
    mask: rows are numbered by group (``image_cell * nb^2 + bi * nb + bj``), then by image."""
    N = block_mask.shape[0]
    kept = np.unpackbits(block_mask, axis=1, count=nb * nb).astype(bool)
    img, blk = np.nonzero(kept)
    gid = image_cell[img].astype(np.int64) * (nb * nb) + blk
    order = np.lexsort((img, gid))
    rows = np.empty(img.shape[0], np.int64)
    rows[order] = np.arange(img.shape[0])
    index = np.full((N, nb * nb), -1, np.int32)
    index[img, blk] = rows
    counts = np.bincount(gid, minlength=n_groups)
    return index.reshape(N, nb, nb), np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _prefix(f):
    """Float32 prefix sums ``(..., n + 1)`` of factors ``(..., n)`` renormalised to sum 1 (undoes
    the rounding of the stored values; zero factors stay zero)."""
    f = f.astype(np.float64)
    s = f.sum(axis=-1, keepdims=True)
    f = np.divide(f, s, out=np.zeros_like(f), where=s > 0)
    out = np.zeros(f.shape[:-1] + (f.shape[-1] + 1,), np.float32)
    out[..., 1:] = np.cumsum(f, axis=-1)
    return out


def decode_v2(a, b, c, c_scale, group_rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float32 prefix sums ``A``, ``Bp`` ``(G, R, B + 1)`` and ``C (K, R)`` of version-2 arrays."""
    prefix = _prefix
    per_row = np.repeat(c_scale.astype(np.float32), np.diff(group_rows), axis=0)
    return prefix(a), prefix(b), (c.astype(np.float32) * per_row)


def save(path: str | os.PathLike, gm: GlintsMap, encoded: dict | None = None) -> None:
    """Write ``gm`` atomically (uncompressed ``np.savez``: deterministic bytes, mmap-able) with
    the ``__meta__`` checksum entry of :func:`prefilter.fileio.save_npz_atomic`.

    ``encoded``: the version-3 arrays of :func:`encode` (the block mask is taken from
    ``gm.block_index``), or the version-2 arrays of :func:`encode_v2`; without them the file is
    written in the version-1 layout (float32 prefix sums). :func:`load` reads all three.
    """
    if encoded is None:
        version, arrays = 1, {k: getattr(gm, k) for k in ARRAYS}
    elif "ranks" in encoded:
        version = 3
        arrays = dict(encoded, block_mask=pack_mask(gm.block_index >= 0),
                      image_cell=gm.image_cell)
    else:
        version = 2
        arrays = dict(encoded, block_index=gm.block_index, image_cell=gm.image_cell)
    header = dict(gm.header, format=FORMAT, version=version)
    save_npz_atomic(path, format_name=FORMAT, format_version=version,
                    header=np.array(json.dumps(header, sort_keys=True)), **arrays)


def _fail(path, msg):
    raise TableFileError(f"glints map {path}: {msg}")


def load(path: str | os.PathLike) -> GlintsMap:
    """Load and validate a baked glints map; any inconsistency (including a checksum mismatch)
    raises ``TableFileError`` naming the file and the field."""
    # the layout is checked before the checksum so a malformed file gets the precise message
    raw_data = read_npz(path, "glints map")
    data = {k: v for k, v in raw_data.items() if k != META_KEY}
    if "header" not in data:
        _fail(path, "missing array 'header'")
    raw = data["header"]
    header = decode_json_object(raw)
    if header is None:
        _fail(path, f"header: expected a JSON object string, got {raw.dtype} {raw.shape}")
    if header.get("format") != FORMAT:
        _fail(path, f"header.format: expected {FORMAT!r}, got {header.get('format')!r}")
    version = header.get("version")
    if version not in (1, 2, VERSION):
        _fail(path, f"header.version: expected 1, 2 or {VERSION}, got {version!r}")
    names = {1: ARRAYS, 2: ARRAYS_V2, 3: ARRAYS_V3}[version]
    missing = [k for k in names if k not in data]
    if missing:
        _fail(path, f"missing arrays {missing}; expected {('header',) + names} (version {version})")
    unknown = [k for k in data if k not in ("header",) + names]
    if unknown:
        _fail(path, f"unknown arrays {unknown}; expected {('header',) + names} (version {version})")
    if version == 1:
        arrays = {k: data[k] for k in ARRAYS}
        stored = None
    elif version == 2:
        arrays = _decode_checked(path, data)
        stored = int(sum(data[k].nbytes for k in ARRAYS_V2))
    else:
        arrays = _decode_checked_v3(path, data, header)
        stored = int(sum(data[k].nbytes for k in ARRAYS_V3))
    try:
        gm = GlintsMap(header=header, **arrays, stored_bytes=stored)
        pyr, R, B, rank = gm.pyramid, gm.resolution, gm.block, gm.rank
        n_images = pyr.n_images
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise TableFileError(f"glints map {path}: header field missing or invalid "
                             f"({type(exc).__name__}: {exc})") from None
    if min(R, B, rank) < 1 or R % B:
        _fail(path, f"header.ndf: expected positive resolution, block and rank with block "
                    f"dividing resolution, got {R}, {B}, {rank}")
    nb = R // B
    if version == 3:
        # the float arrays are decoded on demand from codes checked by _decode_checked_v3:
        # finite, non-negative, non-decreasing prefix sums and C's rows by construction
        G, K = arrays["ranks"].shape[0], int(arrays["codes"]["group_rows"][-1])
        checks = []
    else:
        G = gm.A.shape[0] if gm.A.ndim == 3 else -1
        K = gm.C.shape[0] if gm.C.ndim == 2 else -1
        checks = [("A", gm.A, np.float32, (G, rank, B + 1)),
                  ("Bp", gm.Bp, np.float32, (G, rank, B + 1)),
                  ("C", gm.C, np.float32, (K, rank))]
    checks += [("block_index", gm.block_index, np.int32, (n_images, nb, nb)),
               ("image_cell", gm.image_cell, np.int32, (n_images,))]
    for name, arr, dtype, shape in checks:
        if arr.dtype != dtype or arr.shape != shape:
            _fail(path, f"{name}: expected {np.dtype(dtype)} of shape {shape}, got {arr.dtype} "
                        f"of shape {arr.shape}")
    if gm.block_index.size and (gm.block_index.max() >= K or gm.block_index.min() < -1):
        _fail(path, f"block_index: expected rows of C in [-1, {K})")
    if gm.image_cell.size and (gm.image_cell.min() < 0 or (gm.image_cell.max() + 1) * nb * nb > G):
        _fail(path, f"image_cell: expected cells of the {G} groups")
    for name, _, _, _ in checks[:-2]:
        a = getattr(gm, name)
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            _fail(path, f"{name}: expected finite, non-negative values")
    if version != 3 and (np.any(np.diff(gm.A, axis=-1) < -1e-6)
                         or np.any(np.diff(gm.Bp, axis=-1) < -1e-6)):
        _fail(path, "A, Bp: expected non-decreasing prefix sums")
    verify_npz(path, "glints map", raw_data, format_name=FORMAT, format_version=version)
    return gm


def _decode_checked(path, data) -> dict:
    """Validate the version-2 factor arrays (dtypes, shapes, values) and decode them."""
    a, b, c, sc, rows = (data[k] for k in ("a", "b", "c", "c_scale", "group_rows"))
    for name, arr, dtype, ndim in (("a", a, np.float16, 3), ("b", b, np.float16, 3),
                                   ("c", c, np.float16, 2), ("c_scale", sc, np.float32, 2),
                                   ("group_rows", rows, np.int64, 1)):
        if arr.dtype != dtype or arr.ndim != ndim:
            _fail(path, f"{name}: expected a {ndim}-D {np.dtype(dtype)} array, got {arr.dtype} "
                        f"of shape {arr.shape}")
    G, R, _ = a.shape
    if b.shape != a.shape or sc.shape != (G, R) or c.shape[1:] != (R,) or rows.shape != (G + 1,):
        _fail(path, f"a, b, c, c_scale, group_rows: expected shapes (G, R, B) twice, (K, R), "
                    f"(G, R), (G + 1,), got {a.shape}, {b.shape}, {c.shape}, {sc.shape}, "
                    f"{rows.shape}")
    if rows[0] != 0 or rows[-1] != c.shape[0] or np.any(np.diff(rows) < 0):
        _fail(path, f"group_rows: expected non-decreasing offsets from 0 to {c.shape[0]}")
    for name, arr in (("a", a), ("b", b), ("c", c), ("c_scale", sc)):
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            _fail(path, f"{name}: expected finite, non-negative values")
    A, Bp, C = decode_v2(a, b, c, sc, rows)
    return dict(A=A, Bp=Bp, C=C, block_index=data["block_index"], image_cell=data["image_cell"])


def _decode_checked_v3(path, data, header) -> dict:
    """Validate the version-3 arrays (dtypes, shapes, counts, values) and decode them."""
    arrs = {k: data[k] for k in ARRAYS_V3}
    # the factor codes: a, b both uint8 or both uint16 (code_bits), c either (c_bits)
    code = arrs["a"].dtype if arrs["a"].dtype in (np.uint8, np.uint16) else np.dtype(np.uint8)
    ccode = arrs["c"].dtype if arrs["c"].dtype in (np.uint8, np.uint16) else np.dtype(np.uint8)
    for name, dtype, ndim in (("ranks", np.uint16, 1), ("a", code, 2), ("b", code, 2),
                              ("c", ccode, 1), ("c_scale", np.float32, 1),
                              ("block_mask", np.uint8, 2), ("image_cell", np.int32, 1)):
        arr = arrs[name]
        if arr.dtype != dtype or arr.ndim != ndim:
            _fail(path, f"{name}: expected a {ndim}-D {np.dtype(dtype)} array, got {arr.dtype} "
                        f"of shape {arr.shape}")
    try:
        R, B, width = (int(header["ndf"][k]) for k in ("resolution", "block", "rank"))
        nb = R // B
    except (KeyError, TypeError, ValueError, ZeroDivisionError) as exc:
        raise TableFileError(f"glints map {path}: header field missing or invalid "
                             f"({type(exc).__name__}: {exc})") from None
    ranks, cell, mask = arrs["ranks"], arrs["image_cell"], arrs["block_mask"]
    G, M, N = ranks.shape[0], int(ranks.sum(dtype=np.int64)), cell.shape[0]
    if arrs["a"].shape != (M, B) or arrs["b"].shape != (M, B) or arrs["c_scale"].shape != (M,):
        _fail(path, f"a, b, c_scale: expected shapes ({M}, {B}) twice and ({M},) (sum of ranks, "
                    f"block), got {arrs['a'].shape}, {arrs['b'].shape}, {arrs['c_scale'].shape}")
    if mask.shape != (N, -(-nb * nb // 8)):
        _fail(path, f"block_mask: expected shape ({N}, {-(-nb * nb // 8)}), got {mask.shape}")
    if G % (nb * nb) or (N and (cell.min() < 0 or (int(cell.max()) + 1) * nb * nb > G)):
        _fail(path, f"image_cell: expected cells of the {G} groups ({nb * nb} per cell)")
    if G and int(ranks.max()) > width:
        _fail(path, f"ranks: expected at most header.ndf.rank = {width}, got {int(ranks.max())}")
    index, rows = block_index_from_mask(mask, cell, nb, G)
    need = int(np.sum(np.diff(rows) * ranks.astype(np.int64)))
    if arrs["c"].shape != (need,):
        _fail(path, f"c: expected {need} values (kept blocks x their group's rank), got "
                    f"{arrs['c'].shape[0]}")
    sc = arrs["c_scale"]
    if not np.all(np.isfinite(sc)) or np.any(sc < 0):
        _fail(path, "c_scale: expected finite, non-negative values")
    codes = dict(ranks=ranks, a=arrs["a"], b=arrs["b"], c=arrs["c"], c_scale=sc, group_rows=rows)
    # A, Bp, C: decoded from the codes on first access (GlintsMap), the queries do not need them
    return dict(A=None, Bp=None, C=None, block_index=index, image_cell=cell,
                ranks=ranks.astype(np.int32), codes=codes)
