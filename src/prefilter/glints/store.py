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

from prefilter._io import atomic_path
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
    """Write ``gm`` atomically (uncompressed ``np.savez``: deterministic bytes, mmap-able)."""
    header = dict(gm.header, format=FORMAT, version=VERSION)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, header=np.array(json.dumps(header, sort_keys=True)),
                     **{k: getattr(gm, k) for k in ARRAYS})


def _fail(path, msg):
    raise TableFileError(f"{path}: {msg}")


def load(path: str | os.PathLike) -> GlintsMap:
    """Load and validate a baked glints map; any inconsistency raises ``TableFileError``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            files = set(z.files)
            missing = [k for k in ("header",) + ARRAYS if k not in files]
            if missing:
                _fail(path, f"missing arrays {missing}; expected {('header',) + ARRAYS}")
            header = json.loads(str(z["header"]))
            arrays = {k: z[k] for k in ARRAYS}
    except TableFileError:
        raise
    except (OSError, ValueError, json.JSONDecodeError) as exc:
        raise TableFileError(f"{path}: not a readable glints map ({exc})") from exc
    if header.get("format") != FORMAT:
        _fail(path, f"format {header.get('format')!r}, expected {FORMAT!r}")
    if header.get("version") != VERSION:
        _fail(path, f"version {header.get('version')!r}, expected {VERSION}")
    try:
        gm = GlintsMap(header=header, **arrays)
        pyr, R, B, rank = gm.pyramid, gm.resolution, gm.block, gm.rank
    except (KeyError, TypeError, ValueError) as exc:
        raise TableFileError(f"{path}: header field missing or invalid ({exc})") from exc
    if R % B:
        _fail(path, f"ndf.block {B} does not divide ndf.resolution {R}")
    nb = R // B
    G = gm.A.shape[0]
    checks = [
        (gm.A.dtype == np.float32 and gm.A.shape == (G, rank, B + 1), f"A shape {gm.A.shape}"),
        (gm.Bp.dtype == np.float32 and gm.Bp.shape == gm.A.shape, f"Bp shape {gm.Bp.shape}"),
        (gm.C.dtype == np.float32 and gm.C.ndim == 2 and gm.C.shape[1] == rank,
         f"C shape {gm.C.shape}"),
        (gm.block_index.dtype == np.int32 and gm.block_index.shape == (pyr.n_images, nb, nb),
         f"block_index shape {gm.block_index.shape}, expected {(pyr.n_images, nb, nb)}"),
        (gm.image_cell.dtype == np.int32 and gm.image_cell.shape == (pyr.n_images,),
         f"image_cell shape {gm.image_cell.shape}"),
    ]
    for ok, what in checks:
        if not ok:
            _fail(path, f"inconsistent layout: {what}")
    if gm.block_index.size and (gm.block_index.max() >= gm.C.shape[0] or gm.block_index.min() < -1):
        _fail(path, "block_index points outside C")
    if gm.image_cell.size and (gm.image_cell.min() < 0 or (gm.image_cell.max() + 1) * nb * nb > G):
        _fail(path, "image_cell points outside the groups")
    for name in ("A", "Bp", "C"):
        a = getattr(gm, name)
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            _fail(path, f"{name} has negative or non-finite values")
    if np.any(np.diff(gm.A, axis=-1) < -1e-6) or np.any(np.diff(gm.Bp, axis=-1) < -1e-6):
        _fail(path, "prefix sums are not non-decreasing")
    return gm
