"""On-disk format of per-tile Wang pyramids (:class:`~prefilter.glints.wang_ndf.TiledNDF`).

One uncompressed ``.npz`` (``np.savez``: deterministic bytes), written atomically with the
package's ``__meta__`` checksum entry (:func:`prefilter._io.save_npz_atomic`: SHA-256 over the
names, dtypes, shapes and bytes of all other arrays, plus format name and version). Arrays:

* ``header``: a JSON object string ``{"format": FORMAT, "version": VERSION, "tile": T,
  "seed": hashing seed, "settings": {...}, "arrays": {name: {"dtype", "shape"}}}``; the settings
  are the :class:`TiledNDF` scalars (``ndf_res``, ``support``, ``intrinsic_roughness``,
  ``stride0``, ``sigma0``, ``wide_sigma``, ``uniform_sigma`` (``null`` = never), ``block``,
  ``rank`` (0 = uncompressed), ``k0``, ``cp_error``).
* ``tiles (16, T, T, 3)`` float64: the Wang tiles; ``mean (R, R)``, ``tile_means (16, R, R)``
  float64; ``dependent (n_dep, 2)`` int64 (must equal ``dependent_texels`` of the tiles).
* per level ``l``: ``images_l (16, n_l, n_l, R, R)`` float32, or compressed ``A_l``, ``B_l``
  ``(16, nb^2, rank, B)`` and ``C_l (16, n_l, n_l, nb^2, rank)`` float32 (the CP triple of
  :class:`TiledNDF`).

:func:`load_tiles` checks the layout against the header before the checksum, so a malformed
file gets a precise message; every failure is a :class:`~prefilter.errors.TableFileError`
naming the file and the field.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from prefilter._io import (META_KEY, decode_json_object, read_npz, save_npz_atomic,
                          verify_npz)
from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.pndf import as_intrinsic_roughness, as_support
from prefilter.glints.wang import WangTiles
from prefilter.glints.wang_ndf import TiledNDF, dependent_texels

FORMAT = "prefilter-glints-wang"
VERSION = 1
WHAT = "Wang tiles file"


def _level_arrays(wn: TiledNDF, lv: int) -> dict:
    a = wn.images[lv]
    if isinstance(a, np.ndarray):
        return {f"images_{lv}": a}
    return {f"A_{lv}": a[0], f"B_{lv}": a[1], f"C_{lv}": a[2]}


def save_tiles(wn: TiledNDF, path: str | os.PathLike) -> None:
    """Write ``wn`` (compressed or not) to the ``.npz`` at ``path`` atomically (module docstring
    for the layout)."""
    if not isinstance(wn, TiledNDF):
        raise PrefilterError(f"wn: expected a TiledNDF (bake_tiles), got {type(wn).__name__}")
    if wn.tile_means is None:
        raise PrefilterError("wn: expected per-tile pyramids with tile_means (bake_tiles)")
    arrays = {"tiles": np.asarray(wn.wang.tiles, np.float64),
              "mean": np.asarray(wn.mean, np.float64),
              "tile_means": np.asarray(wn.tile_means, np.float64),
              "dependent": np.asarray(wn.dependent, np.int64)}
    for lv in range(wn.n_levels):
        arrays.update(_level_arrays(wn, lv))
    rank = int(wn.images[0][0].shape[2]) if wn.block else 0
    settings = dict(ndf_res=int(wn.resolution), support=float(wn.support),
                    intrinsic_roughness=float(wn.intrinsic_roughness), stride0=int(wn.stride0),
                    sigma0=float(wn.sigma0), wide_sigma=float(wn.wide_sigma),
                    uniform_sigma=None if math.isinf(wn.uniform_sigma) else float(wn.uniform_sigma),
                    block=int(wn.block), rank=rank, k0=[int(k) for k in wn.k0],
                    cp_error=[float(e) for e in wn.cp_error])
    header = dict(format=FORMAT, version=VERSION, tile=int(wn.wang.size), seed=int(wn.wang.seed),
                  settings=settings,
                  arrays={k: {"dtype": v.dtype.str, "shape": list(v.shape)}
                          for k, v in sorted(arrays.items())})
    save_npz_atomic(path, format_name=FORMAT, format_version=VERSION,
                    header=np.array(json.dumps(header, sort_keys=True)), **arrays)


def _fail(path, msg):
    raise TableFileError(f"{WHAT} {path}: {msg}")


def _header(path, data) -> dict:
    if "header" not in data:
        _fail(path, "missing array 'header'")
    raw = data["header"]
    header = decode_json_object(raw)
    if header is None:
        _fail(path, f"header: expected a JSON object string, got {raw.dtype} {raw.shape}")
    if header.get("format") != FORMAT:
        _fail(path, f"header.format: expected {FORMAT!r}, got {header.get('format')!r}")
    if header.get("version") != VERSION:
        _fail(path, f"header.version: expected {VERSION}, got {header.get('version')!r}")
    return header


def _settings(path, header) -> dict:
    """The header's scalars, typed and range-checked."""
    try:
        st = header["settings"]
        out = dict(T=int(header["tile"]), seed=int(header["seed"]), R=int(st["ndf_res"]),
                   S=as_support(st["support"], "header.settings.support"),
                   sr=as_intrinsic_roughness(st["intrinsic_roughness"],
                                             "header.settings.intrinsic_roughness"),
                   stride0=int(st["stride0"]), sigma0=float(st["sigma0"]),
                   wide=float(st["wide_sigma"]),
                   uniform=math.inf if st["uniform_sigma"] is None else float(st["uniform_sigma"]),
                   B=int(st["block"]), rank=int(st["rank"]), k0=[int(k) for k in st["k0"]],
                   cp_error=[float(e) for e in st["cp_error"]])
        shapes = {k: (str(v["dtype"]), tuple(int(n) for n in v["shape"]))
                  for k, v in header["arrays"].items()}
    except PrefilterError as exc:
        _fail(path, str(exc))
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        _fail(path, f"header field missing or invalid ({type(exc).__name__}: {exc})")
    T, R, B, L = out["T"], out["R"], out["B"], len(out["k0"])
    if T < 4 or T % 2:
        _fail(path, f"header.tile: expected an even tile size >= 4, got {T}")
    if R < 1 or out["stride0"] < 1 or L < 1:
        _fail(path, f"header.settings: expected ndf_res, stride0 and len(k0) >= 1, got {R}, "
                    f"{out['stride0']}, {L}")
    if not (math.isfinite(out["sigma0"]) and out["sigma0"] > 0 and math.isfinite(out["wide"])
            and out["wide"] > 0 and out["uniform"] >= out["wide"]):
        _fail(path, f"header.settings: expected sigma0, wide_sigma > 0 and uniform_sigma >= "
                    f"wide_sigma, got {out['sigma0']}, {out['wide']}, {out['uniform']}")
    if B and (B < 1 or R % B or out["rank"] < 1 or len(out["cp_error"]) != L):
        _fail(path, f"header.settings: expected block dividing ndf_res, rank >= 1 and one cp_error "
                    f"per level, got block {B}, ndf_res {R}, rank {out['rank']}, "
                    f"{len(out['cp_error'])} cp_error for {L} levels")
    if not B and (out["rank"] or out["cp_error"]):
        _fail(path, "header.settings: expected rank 0 and no cp_error when block is 0")
    out["shapes"] = shapes
    return out


def _expected(st) -> dict:
    """Array name -> (dtype, shape with -1 for the crop sizes) implied by the settings."""
    T, R, B, rank = st["T"], st["R"], st["B"], st["rank"]
    out = {"tiles": ("<f8", (16, T, T, 3)), "mean": ("<f8", (R, R)),
           "tile_means": ("<f8", (16, R, R)), "dependent": ("<i8", (-1, 2))}
    nb2 = (R // B) ** 2 if B else 0
    for lv in range(len(st["k0"])):
        if B:
            out[f"A_{lv}"] = out[f"B_{lv}"] = ("<f4", (16, nb2, rank, B))
            out[f"C_{lv}"] = ("<f4", (16, -1, -1, nb2, rank))
        else:
            out[f"images_{lv}"] = ("<f4", (16, -1, -1, R, R))
    return out


def _check_arrays(path, data, st) -> None:
    want = _expected(st)
    names = sorted(want)
    if sorted(st["shapes"]) != names:
        _fail(path, f"header.arrays: expected {names}, got {sorted(st['shapes'])}")
    missing = [k for k in names if k not in data]
    if missing:
        _fail(path, f"missing arrays {missing}; expected {['header'] + names}")
    unknown = sorted(k for k in data if k not in want and k != "header")
    if unknown:
        _fail(path, f"unknown arrays {unknown}; expected {['header'] + names}")
    for k in names:
        a = data[k]
        dtype, shape = want[k]
        ok = (a.dtype.str == dtype and a.ndim == len(shape)
              and all(s in (-1, n) for s, n in zip(shape, a.shape)))
        if not ok or st["shapes"][k] != (a.dtype.str, a.shape):
            _fail(path, f"{k}: expected {np.dtype(dtype)} of shape "
                        f"{tuple('n' if s == -1 else s for s in shape)} as in the header "
                        f"{st['shapes'][k]}, got {a.dtype} of shape {a.shape}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            _fail(path, f"{k}: expected finite values, got NaN or inf")
        if k != "tiles" and np.any(a < 0):
            _fail(path, f"{k}: expected non-negative values")
    for lv in range(len(st["k0"])):
        c = data[f"C_{lv}" if st["B"] else f"images_{lv}"]
        if c.shape[1] != c.shape[2] or c.shape[1] < 1:
            _fail(path, f"level {lv}: expected a square crop of >= 1 centres per axis, got "
                        f"{c.shape[1:3]}")
    t = data["tiles"]
    if np.any(np.abs(np.linalg.norm(t, axis=-1) - 1.0) > 1e-6) or np.any(t[..., 2] <= 0):
        _fail(path, "tiles: expected unit normals with n_z > 0")


def load_tiles(path: str | os.PathLike) -> TiledNDF:
    """Load and validate per-tile Wang pyramids written by :func:`save_tiles`; any inconsistency
    (including a checksum mismatch) raises ``TableFileError`` naming the file and the field."""
    raw = read_npz(path, WHAT)
    data = {k: v for k, v in raw.items() if k != META_KEY}
    st = _settings(path, _header(path, data))
    _check_arrays(path, data, st)
    wang = WangTiles(data["tiles"], st["seed"])
    if not np.array_equal(data["dependent"], np.argwhere(dependent_texels(wang))):
        _fail(path, "dependent: expected the dependent texels of the stored tiles")
    verify_npz(path, WHAT, raw, format_name=FORMAT, format_version=VERSION)
    L, B = len(st["k0"]), st["B"]
    images = tuple((data[f"A_{lv}"], data[f"B_{lv}"], data[f"C_{lv}"]) if B
                   else data[f"images_{lv}"] for lv in range(L))
    return TiledNDF(wang, images, tuple(st["k0"]), data["mean"], st["stride0"], st["sigma0"],
                    st["R"], st["S"], st["sr"], st["wide"], data["dependent"],
                    data["tile_means"], st["uniform"], B, tuple(st["cp_error"]))
