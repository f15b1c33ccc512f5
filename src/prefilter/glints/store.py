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

On disk, version 2 (what :func:`save` writes) stores the factors, not the prefix sums, in float16:
``a``, ``b`` ``(G, R, B)`` float16 (columns renormalised to sum 1 at load), ``c`` ``(K, R)``
float16 scaled per group and rank by ``c_scale (G, R)`` float32 (float16 alone overflows: block sums
of a sharp NDF reach 1e6), ``group_rows (G + 1,)`` int64 (first row of ``c`` of each group), plus
``block_index`` and ``image_cell``; :func:`decode` rebuilds the float32 arrays (the bake measures
its error on exactly these). Version 1 files (float32 prefix sums ``A``, ``Bp``, ``C``) still load.

All factor values are non-negative, so every reconstructed NDF value and range mean is >= 0.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

from prefilter._io import META_KEY, read_npz, save_npz_atomic, verify_npz
from prefilter.errors import TableFileError
from prefilter.glints.pyramid import Pyramid

FORMAT = "prefilter-glints"
VERSION = 2
ARRAYS = ("A", "Bp", "C", "block_index", "image_cell")  # in memory, and on disk in version 1
ARRAYS_V2 = ("a", "b", "c", "c_scale", "group_rows", "block_index", "image_cell")


@dataclass
class GlintsMap:
    """A compressed NDF pyramid (see the module docstring for the arrays)."""

    header: dict
    A: np.ndarray
    Bp: np.ndarray
    C: np.ndarray
    block_index: np.ndarray
    image_cell: np.ndarray
    #: bytes of the arrays as stored on disk (set by :func:`encode` / :func:`load`)
    stored_bytes: int | None = None

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

    def point(self, center, sigma_p, s):
        from prefilter.glints.query import point

        return point(self, center, sigma_p, s)

    def range(self, center, sigma_p, s_min, s_max):
        from prefilter.glints.query import range_mean

        return range_mean(self, center, sigma_p, s_min, s_max)


def encode(a: np.ndarray, b: np.ndarray, c: np.ndarray, group_rows: np.ndarray) -> dict:
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


def decode(a, b, c, c_scale, group_rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float32 prefix sums ``A``, ``Bp`` ``(G, R, B + 1)`` and ``C (K, R)`` of version-2 arrays."""
    def prefix(f):
        f = f.astype(np.float64)
        s = f.sum(axis=-1, keepdims=True)
        f = np.divide(f, s, out=np.zeros_like(f), where=s > 0)  # float16 rounding: sums back to 1
        out = np.zeros(f.shape[:-1] + (f.shape[-1] + 1,), np.float32)
        out[..., 1:] = np.cumsum(f, axis=-1)
        return out

    per_row = np.repeat(c_scale.astype(np.float32), np.diff(group_rows), axis=0)
    return prefix(a), prefix(b), (c.astype(np.float32) * per_row)


def save(path: str | os.PathLike, gm: GlintsMap, encoded: dict | None = None) -> None:
    """Write ``gm`` atomically (uncompressed ``np.savez``: deterministic bytes, mmap-able) with
    the ``__meta__`` checksum entry of :func:`prefilter._io.save_npz_atomic`.

    ``encoded``: the version-2 arrays of :func:`encode`; without them the file is written in the
    version-1 layout (float32 prefix sums), which :func:`load` also reads.
    """
    version = 1 if encoded is None else VERSION
    header = dict(gm.header, format=FORMAT, version=version)
    arrays = ({k: getattr(gm, k) for k in ARRAYS} if encoded is None else
              dict(encoded, block_index=gm.block_index, image_cell=gm.image_cell))
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
    try:
        if raw.dtype.kind != "U" or raw.shape != ():
            raise ValueError
        header = json.loads(str(raw))
        if not isinstance(header, dict):
            raise ValueError
    except ValueError:
        _fail(path, f"header: expected a JSON object string, got {raw.dtype} {raw.shape}")
    if header.get("format") != FORMAT:
        _fail(path, f"header.format: expected {FORMAT!r}, got {header.get('format')!r}")
    version = header.get("version")
    if version not in (1, VERSION):
        _fail(path, f"header.version: expected 1 or {VERSION}, got {version!r}")
    names = ARRAYS if version == 1 else ARRAYS_V2
    missing = [k for k in names if k not in data]
    if missing:
        _fail(path, f"missing arrays {missing}; expected {('header',) + names} (version {version})")
    unknown = [k for k in data if k not in ("header",) + names]
    if unknown:
        _fail(path, f"unknown arrays {unknown}; expected {('header',) + names} (version {version})")
    if version == 1:
        arrays = {k: data[k] for k in ARRAYS}
        stored = None
    else:
        arrays = _decode_checked(path, data)
        stored = int(sum(data[k].nbytes for k in ARRAYS_V2))
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
    G = gm.A.shape[0] if gm.A.ndim == 3 else -1
    checks = [
        ("A", gm.A, np.float32, (G, rank, B + 1)),
        ("Bp", gm.Bp, np.float32, (G, rank, B + 1)),
        ("C", gm.C, np.float32, (gm.C.shape[0] if gm.C.ndim == 2 else -1, rank)),
        ("block_index", gm.block_index, np.int32, (n_images, nb, nb)),
        ("image_cell", gm.image_cell, np.int32, (n_images,)),
    ]
    for name, arr, dtype, shape in checks:
        if arr.dtype != dtype or arr.shape != shape:
            _fail(path, f"{name}: expected {np.dtype(dtype)} of shape {shape}, got {arr.dtype} "
                        f"of shape {arr.shape}")
    if gm.block_index.size and (gm.block_index.max() >= gm.C.shape[0] or gm.block_index.min() < -1):
        _fail(path, f"block_index: expected rows of C in [-1, {gm.C.shape[0]})")
    if gm.image_cell.size and (gm.image_cell.min() < 0 or (gm.image_cell.max() + 1) * nb * nb > G):
        _fail(path, f"image_cell: expected cells of the {G} groups")
    for name in ("A", "Bp", "C"):
        a = getattr(gm, name)
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            _fail(path, f"{name}: expected finite, non-negative values")
    if np.any(np.diff(gm.A, axis=-1) < -1e-6) or np.any(np.diff(gm.Bp, axis=-1) < -1e-6):
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
    A, Bp, C = decode(a, b, c, sc, rows)
    return dict(A=A, Bp=Bp, C=C, block_index=data["block_index"], image_cell=data["image_cell"])
