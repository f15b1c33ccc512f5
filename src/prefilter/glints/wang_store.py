"""On-disk format of per-tile Wang pyramids (:class:`~prefilter.glints.wang_ndf.TiledNDF`).

One uncompressed ``.npz`` (``np.savez``: deterministic bytes), written atomically with the
package's ``__meta__`` checksum entry (:func:`prefilter.fileio.save_npz_atomic`: SHA-256 over the
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

That is version 1, the float32 layout (``save_tiles(code_bits=0)``, and every uncompressed
pyramid). Version 2 (compressed pyramids, ``code_bits`` 8 or 16, the default 8) stores the CP
factors as integer codes, like the glints map store's version 3 (:mod:`prefilter.glints.store`):

* ``tile_means (16, R, R)`` float32; no ``mean`` (it is their float64 average, recomputed at
  load exactly as :func:`~prefilter.glints.wang_ndf.bake_tiles` computes it).
* per level ``l``, with ``K_l`` kept rows of ``C_l`` and ``G_l`` live groups:
  ``mask_l (2 n_l^2 nb^2,)`` uint8, the packed bits (``np.packbits``) of the rows
  ``C_l[t, b, a, g]`` kept (row-major): rows whose codes are all 0 are not
  stored; a group ``(t, g)`` is live when one of its rows is kept, its ``A``, ``B`` are
  stored, in ``(t, g)`` order; ``a_l``, ``b_l (G_l, rank, B)``: each component's factor in
  ``2^code_bits - 1`` steps of its maximum (decoded with maximum 1); ``c_l (K_l, rank)``: the
  kept rows in the same steps of the component's maximum over the centres;
  ``c_scale_l (G_l, rank)`` float32: the product of the three maxima (decoded
  ``C = c / Q * c_scale``, ``Q = 2^code_bits - 1``), so ``A Bf C`` is the stored product up
  to the rounding of the codes. All codes uint8 (``code_bits`` 8) or all uint16 (16).

Version 3 is version 2 plus the vertex pyramids of a compressed bake (the dependent texels per
vertex configuration, :func:`~prefilter.glints.wang_ndf.vertex_tiles`), in the same layout
with a ``v`` before each per-level name (``vmask_l``, ``va_l``, ``vb_l``, ``vc_l``,
``vc_scale_l``) and ``vertex_cp_error``, ``vertex_k0``, ``vertex_crops`` (their centres per
level) in the settings; and, with ``settings.angular_pool`` ``p > 0``, the coarse pyramids
(:attr:`~prefilter.glints.wang_ndf.TiledNDF.coarse`: the images averaged over ``p x p``
pixels, the same centres) of the tiles and of the vertices, ``g`` and ``gv`` before the same
names (``gmask_l``, ..., ``gvc_scale_l``), their errors ``coarse_cp_error``,
``coarse_vertex_cp_error``.
Version 4 is version 3 plus ``moment_sat (R + 1, R + 1, 16, 5)`` float32, the summed-area
tables of the tiles' in-tile moment images (:func:`~prefilter.glints.wang_ndf.moment_tables`
of :func:`~prefilter.glints.wang_ndf.tile_moment_images`: the tile-type shares regime's
corrections, signed). Files of versions 1 to 3 get them computed from their tiles at load.
:func:`save_tiles` writes version 4 for pyramids with vertex pyramids, version 2 for those
without; ``code_bits`` 0 (version 1) writes no vertex pyramids (the queries then compute the
dependent texels exactly, as for uncompressed pyramids).

A loaded version-2, 3 or 4 file is held as its codes, packed for the query kernels
(:func:`prefilter.glints.wang_query.pack_codes`; :attr:`TiledNDF.nbytes` counts the pack), the
float32 triple decoded from the pack on first use by the per-footprint NumPy paths only.
Version 1 files still load.

:func:`load_tiles` checks the layout against the header before the checksum, so a malformed
file gets a precise message; every failure is a :class:`~prefilter.errors.TableFileError`
naming the file and the field.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from prefilter.fileio import (META_KEY, decode_json_object, read_npz, save_npz_atomic,
                          verify_npz)
from prefilter.errors import PrefilterError, TableFileError
from prefilter.glints.pndf import as_intrinsic_roughness, as_support
from prefilter.glints.store import CODE_DTYPES, code_levels
from prefilter.glints.wang import WangTiles
from prefilter.glints.wang_ndf import (TiledNDF, dependent_texels, moment_tables, pooled_tables,
                                      tile_moment_images)
from prefilter.glints.wang_query import DecodedLevels, pack_codes

FORMAT = "prefilter-glints-wang"
VERSION = 4
WHAT = "Wang tiles file"
#: ``code_bits`` of :func:`save_tiles`: 0 = float32 factors (version 1), 8 / 16 = codes
CODE_BITS = (0, 8, 16)


def encode_level(A: np.ndarray, Bf: np.ndarray, C: np.ndarray, code_bits: int = 8) -> dict:
    """Version-2 arrays ``mask``, ``a``, ``b``, ``c``, ``c_scale`` (module docstring) of one
    compressed level: ``A``, ``Bf (16, nb^2, rank, B)``, ``C (16, n, n, nb^2, rank)``
    non-negative (the CP triple of :class:`TiledNDF`); codes of ``code_bits`` (8 or 16) bits."""
    if code_bits not in CODE_DTYPES:
        raise PrefilterError(f"code_bits: expected 8 or 16, got {code_bits!r}")
    dt = CODE_DTYPES[code_bits]
    Q = float(code_levels(dt))

    def codes(f, m):  # f / m in Q steps, 0 where the component is 0
        return np.rint(np.divide(Q * f, m, out=np.zeros(f.shape), where=m > 0)).astype(dt)

    A, Bf, C = (np.asarray(x, np.float64) for x in (A, Bf, C))
    ma, mb = A.max(axis=-1), Bf.max(axis=-1)  # (16, nb^2, rank)
    mc = C.max(axis=(1, 2))
    qc = codes(C, mc[:, None, None])
    kept = qc.max(axis=-1) > 0  # (16, n, n, nb^2)
    live = kept.any(axis=(1, 2))  # (16, nb^2)
    return dict(mask=np.packbits(kept.ravel()), a=codes(A, ma[..., None])[live],
                b=codes(Bf, mb[..., None])[live], c=qc[kept],
                c_scale=(ma * mb * mc)[live].astype(np.float32))


def decode_level(mask, a, b, c, c_scale, crop: int, n_groups: int):
    """Float32 CP triple ``A``, ``Bf (16, nb^2, rank, B)``, ``C (16, n, n, nb^2, rank)``
    (``n = crop``, ``nb^2 = n_groups``) of one level's version-2 arrays (module docstring)."""
    rank, B = a.shape[1], a.shape[2]
    inv = np.float32(1.0 / code_levels(c.dtype))
    kept = np.unpackbits(mask, count=16 * crop * crop * n_groups).astype(bool)
    kept = kept.reshape(16, crop, crop, n_groups)
    live = kept.any(axis=(1, 2))
    A = np.zeros((16, n_groups, rank, B), np.float32)
    Bf = np.zeros_like(A)
    A[live] = a.astype(np.float32) * inv
    Bf[live] = b.astype(np.float32) * inv
    scale = np.zeros((16, n_groups, rank), np.float32)
    scale[live] = c_scale
    t, _, _, g = np.nonzero(kept)
    C = np.zeros((16, crop, crop, n_groups, rank), np.float32)
    C[kept] = c.astype(np.float32) * inv * scale[t, g]
    return A, Bf, C


def _level_arrays(wn: TiledNDF, lv: int, code_bits: int, vertex: bool = False) -> dict:
    if vertex:  # version 3's vertex pyramids: codes only
        return {f"v{k}_{lv}": v for k, v in encode_level(*wn.vertex_images[lv], code_bits).items()}
    a = wn.images[lv]
    if isinstance(a, np.ndarray):
        return {f"images_{lv}": a}
    if not code_bits:
        return {f"A_{lv}": a[0], f"B_{lv}": a[1], f"C_{lv}": a[2]}
    return {f"{k}_{lv}": v for k, v in encode_level(*a, code_bits).items()}


def save_tiles(wn: TiledNDF, path: str | os.PathLike, *, code_bits: int = 8) -> None:
    """Write ``wn`` (compressed or not) to the ``.npz`` at ``path`` atomically (module docstring
    for the layout). ``code_bits``: 8 or 16, compressed pyramids in version 4 (integer codes of
    the CP factors, with the vertex pyramids and the moment tables; version 2 without them);
    0, the float32 factors (version 1, no vertex pyramids). Uncompressed pyramids are written
    in version 1 whatever ``code_bits``."""
    if not isinstance(wn, TiledNDF):
        raise PrefilterError(f"wn: expected a TiledNDF (bake_tiles), got {type(wn).__name__}")
    if wn.tile_means is None:
        raise PrefilterError("wn: expected per-tile pyramids with tile_means (bake_tiles)")
    if isinstance(code_bits, bool) or code_bits not in CODE_BITS:
        raise PrefilterError(f"code_bits: expected one of {CODE_BITS}, got {code_bits!r}")
    code_bits = int(code_bits) if wn.block else 0
    vertex = bool(code_bits and wn.vertex_images)
    version = (VERSION if vertex else 2) if code_bits else 1
    cwn = wn.coarse if version == VERSION and wn.coarse is not None and wn.coarse.vertex_images \
        else None
    # version 1: the arrays in the order (hence the bytes) of the files written before version 2
    arrays = {"tiles": np.asarray(wn.wang.tiles, np.float64)}
    if version == 1:
        arrays.update(mean=np.asarray(wn.mean, np.float64),
                      tile_means=np.asarray(wn.tile_means, np.float64))
    else:
        arrays.update(tile_means=np.asarray(wn.tile_means, np.float32))
    arrays["dependent"] = np.asarray(wn.dependent, np.int64)
    if version == VERSION:
        arrays["moment_sat"] = np.asarray(_moment_sat(wn), np.float32)
    for lv in range(wn.n_levels):
        arrays.update(_level_arrays(wn, lv, code_bits))
        if vertex:
            arrays.update(_level_arrays(wn, lv, code_bits, vertex=True))
        if cwn is not None:
            for v in (False, True):
                arrays.update({"g" + k: a for k, a in _level_arrays(cwn, lv, code_bits,
                                                                    vertex=v).items()})
    rank = int(wn.pack.meta[:, 0].max()) if wn.block else 0
    settings = dict(ndf_res=int(wn.resolution), support=float(wn.support),
                    intrinsic_roughness=float(wn.intrinsic_roughness), stride0=int(wn.stride0),
                    sigma0=float(wn.sigma0), wide_sigma=float(wn.wide_sigma),
                    uniform_sigma=None if math.isinf(wn.uniform_sigma) else float(wn.uniform_sigma),
                    block=int(wn.block), rank=rank, k0=[int(k) for k in wn.k0],
                    cp_error=[float(e) for e in wn.cp_error])
    if version >= 2:
        settings.update(code_bits=code_bits, crops=[wn.crop(lv) for lv in range(wn.n_levels)])
    if version == VERSION:
        settings.update(vertex_cp_error=[float(e) for e in wn.vertex_cp_error],
                        vertex_k0=[int(k) for k in wn.vertex_k0],
                        vertex_crops=[wn.vertex_crop(lv) for lv in range(wn.n_levels)],
                        angular_pool=0 if cwn is None else wn.resolution // cwn.resolution,
                        coarse_cp_error=[] if cwn is None else [float(e) for e in
                                                                cwn.cp_error],
                        coarse_vertex_cp_error=[] if cwn is None else [
                            float(e) for e in cwn.vertex_cp_error])
    header = dict(format=FORMAT, version=version, tile=int(wn.wang.size),
                  seed=int(wn.wang.seed), settings=settings,
                  arrays={k: {"dtype": v.dtype.str, "shape": list(v.shape)}
                          for k, v in sorted(arrays.items())})
    save_npz_atomic(path, format_name=FORMAT, format_version=version,
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
    version = header.get("version")
    if isinstance(version, bool) or version not in (1, 2, 3, VERSION):
        _fail(path, f"header.version: expected 1, 2, 3 or {VERSION}, got {version!r}")
    return header


def _settings(path, header) -> dict:
    """The header's scalars, typed and range-checked."""
    v2 = header["version"] >= 2  # the codes (version 3: also the vertex pyramids')
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
                   cp_error=[float(e) for e in st["cp_error"]], version=header["version"],
                   code_bits=int(st["code_bits"]) if v2 else 0,
                   crops=[int(n) for n in st["crops"]] if v2 else None, pool=0,
                   vertex_cp_error=[], vertex_k0=[], vertex_crops=[], coarse_cp_error=[],
                   coarse_vertex_cp_error=[])
        if header["version"] >= 3:
            out.update(vertex_cp_error=[float(e) for e in st["vertex_cp_error"]],
                       vertex_k0=[int(k) for k in st["vertex_k0"]],
                       vertex_crops=[int(n) for n in st["vertex_crops"]],
                       pool=int(st["angular_pool"]),
                       coarse_cp_error=[float(e) for e in st["coarse_cp_error"]],
                       coarse_vertex_cp_error=[float(e) for e in st["coarse_vertex_cp_error"]])
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
    if v2:
        if out["code_bits"] not in CODE_DTYPES or not B:
            _fail(path, f"header.settings.code_bits: expected 8 or 16 with block > 0 "
                        f"(version {out['version']}), got {out['code_bits']} with block {B}")
        if len(out["crops"]) != L or min(out["crops"]) < 1:
            _fail(path, f"header.settings.crops: expected {L} crop sizes >= 1 (one per level), "
                        f"got {out['crops']}")
    if out["version"] >= 3:
        for k in ("vertex_cp_error", "vertex_k0", "vertex_crops"):
            if len(out[k]) != L:
                _fail(path, f"header.settings.{k}: expected one per level ({L}), got "
                            f"{len(out[k])}")
        if min(out["vertex_crops"]) < 1:
            _fail(path, f"header.settings.vertex_crops: expected crop sizes >= 1, got "
                        f"{out['vertex_crops']}")
        p = out["pool"]
        if p and (p < 2 or R % p or (R // p) % B):
            _fail(path, f"header.settings.angular_pool: expected 0 or a divisor p >= 2 of "
                        f"ndf_res {R} with ndf_res / p a multiple of block {B}, got {p}")
        for k in ("coarse_cp_error", "coarse_vertex_cp_error"):
            if len(out[k]) != (L if p else 0):
                _fail(path, f"header.settings.{k}: expected {L if p else 0} entries, got "
                            f"{len(out[k])}")
    out["shapes"] = shapes
    return out


def _code_sets(st) -> tuple:
    """The prefixes of a version-2 or 3 file's code arrays: ``""`` the tiles, ``"v"`` the
    vertex pyramids, ``"g"``, ``"gv"`` the coarse ones (module docstring)."""
    if st["version"] < 3:
        return ("",)
    return ("", "v", "g", "gv") if st["pool"] else ("", "v")


def _code_layout(st, v: str, lv: int) -> tuple[int, int]:
    """Centres per axis and angular blocks per image of level ``lv`` of code set ``v``."""
    n = st["vertex_crops" if "v" in v else "crops"][lv]
    return n, (st["R"] // (st["pool"] if "g" in v else 1) // st["B"]) ** 2


def _packed(data, st, v: str):
    """:func:`~prefilter.glints.wang_query.pack_codes` of code set ``v``'s levels."""
    L = len(st["k0"])
    levels = [{k: data[f"{v}{k}_{lv}"] for k in ("mask", "a", "b", "c", "c_scale")}
              for lv in range(L)]
    return pack_codes(levels, [_code_layout(st, v, lv)[0] for lv in range(L)],
                      _code_layout(st, v, 0)[1])


def _expected(st) -> dict:
    """Array name -> (dtype, shape with -1 for the sizes the header does not fix) implied by
    the settings."""
    T, R, B, rank = st["T"], st["R"], st["B"], st["rank"]
    v2 = st["version"] >= 2
    out = {"tiles": ("<f8", (16, T, T, 3)), "tile_means": ("<f4" if v2 else "<f8", (16, R, R)),
           "dependent": ("<i8", (-1, 2))}
    if st["version"] >= 4:
        out["moment_sat"] = ("<f4", (R + 1, R + 1, 16, 5))
    if not v2:
        out["mean"] = ("<f8", (R, R))
    nb2 = (R // B) ** 2 if B else 0
    code = np.dtype(CODE_DTYPES[st["code_bits"]]).str if v2 else None
    for lv in range(len(st["k0"])):
        if v2:
            for v in _code_sets(st):
                n, g2 = _code_layout(st, v, lv)
                out[f"{v}mask_{lv}"] = ("|u1", (2 * n * n * g2,))  # 16 n^2 nb^2 bits
                out[f"{v}a_{lv}"] = out[f"{v}b_{lv}"] = (code, (-1, rank, B))
                out[f"{v}c_{lv}"] = (code, (-1, rank))
                out[f"{v}c_scale_{lv}"] = ("<f4", (-1, rank))
        elif B:
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
            dims = ["n" if s == -1 else str(s) for s in shape]
            _fail(path, f"{k}: expected {np.dtype(dtype)} of shape "
                        f"({', '.join(dims)}{',' if len(dims) == 1 else ''}) as in the header "
                        f"{st['shapes'][k]}, got {a.dtype} of shape {a.shape}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            _fail(path, f"{k}: expected finite values, got NaN or inf")
        if k not in ("tiles", "moment_sat") and np.any(a < 0):
            _fail(path, f"{k}: expected non-negative values")
    for lv in range(len(st["k0"])):
        if st["version"] >= 2:
            for v in _code_sets(st):
                _check_codes(path, data, st, lv, v)
            continue
        c = data[f"C_{lv}" if st["B"] else f"images_{lv}"]
        if c.shape[1] != c.shape[2] or c.shape[1] < 1:
            _fail(path, f"level {lv}: expected a square crop of >= 1 centres per axis, got "
                        f"{c.shape[1:3]}")
    t = data["tiles"]
    if np.any(np.abs(np.linalg.norm(t, axis=-1) - 1.0) > 1e-6) or np.any(t[..., 2] <= 0):
        _fail(path, "tiles: expected unit normals with n_z > 0")


def _check_codes(path, data, st, lv, v="") -> None:
    """Versions 2 and 3: the numbers of kept rows and live groups of level ``lv``'s mask
    against the code arrays (their dtypes and the other dimensions are checked by
    :func:`_check_arrays`) of code set ``v`` (:func:`_code_sets`)."""
    n, nb2 = _code_layout(st, v, lv)
    kept = np.unpackbits(data[f"{v}mask_{lv}"]).astype(bool).reshape(16, n * n, nb2)
    K, G = int(kept.sum()), int(kept.any(axis=1).sum())
    got = [data[f"{v}{k}_{lv}"].shape[0] for k in ("c", "a", "b", "c_scale")]
    if got != [K, G, G, G]:
        _fail(path, f"{v}c_{lv}, {v}a_{lv}, {v}b_{lv}, {v}c_scale_{lv}: expected {K} rows (kept "
                    f"rows of {v}mask_{lv}) and {G} live groups, got {got[0]}, {got[1]}, "
                    f"{got[2]}, {got[3]}")


def load_tiles(path: str | os.PathLike) -> TiledNDF:
    """Load and validate per-tile Wang pyramids written by :func:`save_tiles` (version 1, 2 or
    3; version 2 and 3's codes are packed for the kernels, :attr:`TiledNDF.packed` and
    :attr:`TiledNDF.vertex_packed`); any inconsistency (including a checksum mismatch) raises
    ``TableFileError`` naming the file and the field."""
    raw = read_npz(path, WHAT)
    data = {k: v for k, v in raw.items() if k != META_KEY}
    st = _settings(path, _header(path, data))
    _check_arrays(path, data, st)
    wang = WangTiles(data["tiles"], st["seed"])
    if not np.array_equal(data["dependent"], np.argwhere(dependent_texels(wang))):
        _fail(path, "dependent: expected the dependent texels of the stored tiles")
    verify_npz(path, WHAT, raw, format_name=FORMAT, format_version=st["version"])
    L, B = len(st["k0"]), st["B"]
    # the tile-type shares regime's moment tables: stored from version 4, computed from the
    # tiles for older files (the same function of the tiles as the bake's)
    msat = (data["moment_sat"] if st["version"] >= 4 else
            moment_tables(tile_moment_images(wang, st["R"], st["S"], st["sr"])))
    packed = vpacked = coarse = None
    vimages = ()
    if st["version"] >= 2:
        # the codes packed as stored (the kernels read them; wang_query.pack_codes), the
        # float32 triples decoded on first use by the per-footprint paths only
        packed = _packed(data, st, "")
        images = DecodedLevels(packed)
        if st["version"] >= 3:
            vpacked = _packed(data, st, "v")
            vimages = DecodedLevels(vpacked)
        tile_means = data["tile_means"]
        mean = tile_means.astype(np.float64).mean(axis=0)
        if st["version"] >= 3 and st["pool"]:
            coarse = _coarse(data, st, tile_means, wang, msat)
    else:
        images = tuple((data[f"A_{lv}"], data[f"B_{lv}"], data[f"C_{lv}"]) if B
                       else data[f"images_{lv}"] for lv in range(L))
        tile_means, mean = data["tile_means"], data["mean"]
    return TiledNDF(wang, images, tuple(st["k0"]), mean, st["stride0"], st["sigma0"],
                    st["R"], st["S"], st["sr"], st["wide"], data["dependent"],
                    tile_means, st["uniform"], B, tuple(st["cp_error"]), packed, vimages,
                    tuple(st["vertex_cp_error"]), vpacked, tuple(st["vertex_k0"]), coarse,
                    msat)


def _moment_sat(wn: TiledNDF) -> np.ndarray:
    """``wn``'s moment tables, computed from its tiles when it has none (a ``TiledNDF`` built
    by hand)."""
    if wn.moment_sat is not None:
        return wn.moment_sat
    return moment_tables(tile_moment_images(wn.wang, wn.resolution, wn.support,
                                            wn.intrinsic_roughness))


def _coarse(data, st, tile_means, wang, msat) -> TiledNDF:
    """The coarse pyramids of a version-3 or 4 file with ``angular_pool``, packed as stored."""
    B, p = st["B"], st["pool"]
    Rc = st["R"] // p
    packs = [_packed(data, st, v) for v in ("g", "gv")]
    tm = tile_means.astype(np.float64).reshape(16, Rc, p, Rc, p).mean(axis=(2, 4))
    return TiledNDF(wang, DecodedLevels(packs[0]),
                    tuple(st["k0"]), tm.mean(axis=0), st["stride0"], st["sigma0"], Rc, st["S"],
                    st["sr"], st["wide"], data["dependent"], tm, st["uniform"], B,
                    tuple(st["coarse_cp_error"]), packs[0], DecodedLevels(packs[1]),
                    tuple(st["coarse_vertex_cp_error"]), packs[1], tuple(st["vertex_k0"]),
                    None, pooled_tables(msat, p))
