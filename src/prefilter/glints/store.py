"""On-disk format of a baked glints map: one ``.npz`` with a JSON header, versioned.

Arrays (``G`` groups, ``R`` rank, ``B`` block size, ``nb = ndf_res / B``, ``N`` images):

* ``header``: JSON text (format, version, pyramid, NDF image geometry, settings, bake summary).
* ``A``, ``Bp`` ``(G, R, B + 1)`` float32: 1D prefix sums of the row / column factors ``a_r``, ``b_r``
  of each group (columns sum to 1, so each prefix sum runs from 0 to 1).
* ``C`` ``(K, R)`` float32: the third factors with the CP weights folded in, one row per kept block.
* ``block_index`` ``(N, nb, nb)`` int32: row of ``C`` of block ``[bi, bj]`` of each image, -1 = blank.
* ``image_cell`` ``(N,)`` int32: spatial cell of each image; the group of block ``[bi, bj]`` of an
  image is ``image_cell * nb^2 + bi * nb + bj``.

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
VERSION = 1
ARRAYS = ("A", "Bp", "C", "block_index", "image_cell")


@dataclass
class GlintsMap:
    """A compressed NDF pyramid (see the module docstring for the arrays)."""

    header: dict
    A: np.ndarray
    Bp: np.ndarray
    C: np.ndarray
    block_index: np.ndarray
    image_cell: np.ndarray

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
        return int(sum(getattr(self, k).nbytes for k in ARRAYS))

    def point(self, center, sigma_p, s):
        from prefilter.glints.query import point

        return point(self, center, sigma_p, s)

    def range(self, center, sigma_p, s_min, s_max):
        from prefilter.glints.query import range_mean

        return range_mean(self, center, sigma_p, s_min, s_max)


def save(path: str | os.PathLike, gm: GlintsMap) -> None:
    """Write ``gm`` atomically (uncompressed ``np.savez``: deterministic bytes, mmap-able) with
    the ``__meta__`` checksum entry of :func:`prefilter._io.save_npz_atomic`."""
    header = dict(gm.header, format=FORMAT, version=VERSION)
    save_npz_atomic(path, format_name=FORMAT, format_version=VERSION,
                    header=np.array(json.dumps(header, sort_keys=True)),
                    **{k: getattr(gm, k) for k in ARRAYS})


def _fail(path, msg):
    raise TableFileError(f"glints map {path}: {msg}")


def load(path: str | os.PathLike) -> GlintsMap:
    """Load and validate a baked glints map; any inconsistency (including a checksum mismatch)
    raises ``TableFileError`` naming the file and the field."""
    # the layout is checked before the checksum so a malformed file gets the precise message
    raw_data = read_npz(path, "glints map")
    data = {k: v for k, v in raw_data.items() if k != META_KEY}
    missing = [k for k in ("header",) + ARRAYS if k not in data]
    if missing:
        _fail(path, f"missing arrays {missing}; expected {('header',) + ARRAYS}")
    unknown = [k for k in data if k not in ("header",) + ARRAYS]
    if unknown:
        _fail(path, f"unknown arrays {unknown}; expected {('header',) + ARRAYS}")
    raw = data["header"]
    try:
        if raw.dtype.kind != "U" or raw.shape != ():
            raise ValueError
        header = json.loads(str(raw))
        if not isinstance(header, dict):
            raise ValueError
    except ValueError:
        _fail(path, f"header: expected a JSON object string, got {raw.dtype} {raw.shape}")
    arrays = {k: data[k] for k in ARRAYS}
    if header.get("format") != FORMAT:
        _fail(path, f"header.format: expected {FORMAT!r}, got {header.get('format')!r}")
    if header.get("version") != VERSION:
        _fail(path, f"header.version: expected {VERSION}, got {header.get('version')!r}")
    try:
        gm = GlintsMap(header=header, **arrays)
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
    verify_npz(path, "glints map", raw_data, format_name=FORMAT, format_version=VERSION)
    return gm
