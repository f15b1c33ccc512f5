"""A baked glints map as WebGL2 textures, and the GLSL that queries them (glints paper, eqs. 6-7
and sec. 5.1, on the GPU).

Every array of the query kernels (:func:`prefilter.glints.query.packed`) becomes one
``TEXTURE_2D_ARRAY`` (single-channel but ``c``, ``meta`` and ``elements``): flat element ``k`` is
texel ``(k % w, (k / w) % h)`` of layer ``k / (w h)``, with ``w = min(n, MAX_TEXTURE_SIZE)`` and
``h`` up to ``MAX_TEXTURE_SIZE`` rows per
layer. Textures (``M``: components, sum of the groups' ranks; ``B``: block; ``G`` groups; ``N``
images; ``nb = R / B`` blocks per axis; layout of each in :mod:`prefilter.glints._qkernels`):

* ``fa``, ``fb`` ``(M B)``: the row / column factors, rank-innermost per group;
* ``pa``, ``pb`` ``(M (B + 1))``: their prefix sums (the range query);
* ``c`` RGBA (4 components a texel): the third factors' code rows in use, each in whole texels
  (zero-padded), so a tap reads ``ceil(r / 4)`` texels;
* ``w`` ``(M,)`` float32: the scale of each component, so that an NDF pixel of a block of group
  ``g`` is ``sum_r w[m + r] c[kc, r] fa[i, r] fb[j, r]``;
* ``meta`` ``(G,)`` RGBA32I: rank, first component, 0, 1 (code-row base and stride: ``index``
  holds the rows' texels);
* ``index`` ``(N nb nb)`` R32I: the first texel in ``c`` of the code row of block ``(bi, bj)`` of
  each image (-1: blank);
  ``cell`` ``(N,)`` R32I: the image's cell (group ``cell nb^2 + bi nb + bj``);
* ``elements`` ``(2 H W)`` RGBA32F: per texel of the normal map ``(s_x, s_y, |J|_F, 0)`` and
  its Jacobian ``(J00, J01, J10, J11)`` (:func:`prefilter.glints.pndf.elements`), for the direct
  P-NDF below the finest level.

Code variants (:data:`CODE_FORMATS`): ``"f32"`` (the stored codes as float32: exact for 8- and
16-bit codes, ``w`` = the kernels' ``wsc``), ``"f16"`` (factors and prefix sums divided by each
component's code sum, IEEE half; ``c`` in half, exact for 8-bit codes), ``"u8"`` (factors
requantised to 8 bits of each component's maximum, ``c`` in 8 bits, ``R8`` / ``RGBA8`` UNORM; prefix
sums of the 8-bit factors in float32).

Limits (:data:`WEBGL2_LIMITS`, the minima every WebGL2 implementation guarantees):
``MAX_TEXTURE_SIZE`` 2048, ``MAX_ARRAY_TEXTURE_LAYERS`` 256, ``MAX_3D_TEXTURE_SIZE`` 256 (unused:
2D arrays hold 2048 x 2048 x 256 = 2^30 texels each at the minima, 3D textures only 2^24). An
export whose texture exceeds a limit, or whose flat indices exceed int32, is refused with a
:class:`~prefilter.errors.PrefilterError` naming the texture and the limit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.fileio import atomic_path
from prefilter.glints.pndf import SIGMA_H, elements
from prefilter.glints.pyramid import RESAMPLE_Q_MIN, RESAMPLE_TRUNCATION, resample_min_sigma
from prefilter.glints.query import packed
from prefilter.glints.store import GlintsMap, code_levels

__all__ = ["CODE_FORMATS", "MAX_LEVELS", "MAX_RECTS", "SUM_SIZE", "SUM_SLOTS", "WEBGL2_LIMITS",
           "export_gpu", "export_surface", "glsl_source", "slope_moments", "texture_shape",
           "write_gpu"]

#: WebGL2's guaranteed minima (WebGL 2.0 spec, sec. 6.3 / OpenGL ES 3.0 table 6.28).
WEBGL2_LIMITS = {"MAX_TEXTURE_SIZE": 2048, "MAX_ARRAY_TEXTURE_LAYERS": 256,
                 "MAX_3D_TEXTURE_SIZE": 256}
CODE_FORMATS = ("f32", "f16", "u8")
#: Pyramid levels the GLSL's uniform arrays hold (a 4096^2 map at stride 4 has 11).
MAX_LEVELS = 12
#: The queries' per-group sums of the taps' code rows: at most ``SUM_SLOTS`` CP groups and
#: ``SUM_SIZE`` components in all at once (more are flushed and restarted, still exact); a group
#: of a higher rank than ``SUM_SIZE`` is refused by :func:`export_gpu`.
SUM_SLOTS = 16
SUM_SIZE = 512
#: Rectangles of one ``glRangeMulti`` call (a quad light's 4 x 4 patches).
MAX_RECTS = 16
#: Direct P-NDF below the finest level: truncation in stds (the ``glints`` method's
#: :data:`prefilter.glints.brdf.FALLBACK_TRUNCATION`).
FALLBACK_TRUNCATION = 4.0
GLSL_DIR = Path(__file__).resolve().parent / "glsl"
#: The snippets in the order they are concatenated (each uses the ones before it).
GLSL_FILES = ("glints_textures.glsl", "glints_query.glsl", "glints_pndf.glsl",
              "glints_brdf.glsl")
_INT32_MAX = 2**31 - 1


def texture_shape(n: int, name: str, limits: dict | None = None) -> tuple[int, int, int]:
    """``(width, height, layers)`` of the 2D array texture holding ``n`` flat values (see the
    module docstring); a :class:`PrefilterError` naming ``name`` and the limit it exceeds."""
    lim = dict(WEBGL2_LIMITS, **(limits or {}))
    size, max_layers = int(lim["MAX_TEXTURE_SIZE"]), int(lim["MAX_ARRAY_TEXTURE_LAYERS"])
    if n > _INT32_MAX:
        raise PrefilterError(f"glints texture {name}: {n} values exceed the shader's int32 "
                             f"indices ({_INT32_MAX})")
    w = max(1, min(int(n), size))
    rows = max(1, -(-int(n) // w))
    h = min(rows, size)
    layers = -(-rows // h)
    if layers > max_layers:
        raise PrefilterError(
            f"glints texture {name}: {n} values need {layers} layers of {w} x {h} texels, more "
            f"than MAX_ARRAY_TEXTURE_LAYERS = {max_layers} (MAX_TEXTURE_SIZE = {size}); bake a "
            "smaller map or a lower rank, or pass the browser's larger limits")
    return w, h, layers


def _components(meta, M, B):
    """Flat indices ``(M, B)`` of each component's factor values in the rank-innermost layout
    (component ``m_g + r`` of group ``g``: ``m_g B + i r_g + r``)."""
    r = meta[:, 0].astype(np.int64)
    m0 = meta[:, 1].astype(np.int64)
    g = np.repeat(np.arange(len(r)), r)
    comp = np.arange(M)
    base = m0[g] * B + (comp - m0[g])
    return base[:, None] + np.arange(B)[None, :] * r[g][:, None]


def _code_texels(cq, meta, block_index, image_cell, nb):
    """The code rows in use re-laid for RGBA texels, each in whole texels (zero-padded): returns
    ``texels (T, 4)``, ``meta (G, 4)`` with code-row base 0 and stride 1, and ``index`` like
    ``block_index`` holding the first texel of each block's code row (-1: blank)."""
    meta = np.asarray(meta, np.int64)
    idx = np.asarray(block_index, np.int64)
    g = (np.asarray(image_cell, np.int64)[:, None, None] * nb * nb
         + np.arange(nb)[None, :, None] * nb + np.arange(nb)[None, None, :])
    used = idx >= 0
    gu = g[used]
    start = meta[gu, 2] + idx[used] * meta[gu, 3]
    rows, first, inv = np.unique(start, return_index=True, return_inverse=True)
    r = meta[gu[first], 0]
    s4 = (r + 3) // 4
    off = np.cumsum(s4) - s4
    out = np.zeros((int(s4.sum()), 4), np.asarray(cq).dtype)
    u = np.repeat(np.arange(len(rows)), r)
    c = np.arange(len(u)) - np.repeat(np.cumsum(r) - r, r)
    out.reshape(-1)[4 * off[u] + c] = np.asarray(cq)[rows[u] + c]
    index = np.full(idx.shape, -1, np.int64)
    index[used] = off[inv.reshape(-1)]
    m2 = meta.copy()
    m2[:, 2], m2[:, 3] = 0, 1
    return out, m2, index


def _prefix_layout(vals, meta, B):
    """Prefix sums ``(M, B + 1)`` of per-component values ``(M, B)`` in the kernels'
    rank-innermost flat layout ``m_g (B + 1) + i r_g + r``."""
    M = vals.shape[0]
    pre = np.zeros((M, B + 1), np.float64)
    pre[:, 1:] = np.cumsum(vals, axis=1)
    idx = _components(meta, M, B + 1)  # same rule with B + 1 rows
    out = np.zeros(M * (B + 1), np.float64)
    out[idx] = pre
    return out


def slope_moments(normal_map, intrinsic_roughness: float) -> dict:
    """Mean ``(2,)`` and covariance ``(2, 2)`` of the projected normals ``s`` of a normal map
    plus the intrinsic roughness: the moments of the footprint NDF of the whole map (the top of
    the pyramid), for a smooth Gaussian lobe in ``s`` to compare the glints with."""
    s, _ = elements(normal_map)
    s = s.reshape(-1, 2)
    mu = s.mean(axis=0)
    cov = np.cov(s.T, bias=True) + float(intrinsic_roughness) ** 2 * np.eye(2)
    return {"mean": mu.tolist(), "cov": cov.tolist()}


def export_gpu(gm: GlintsMap, normal_map=None, *, codes: str = "f32", limits: dict | None = None,
               intrinsic_roughness: float | None = None) -> dict:
    """The textures and parameters of a baked map for the GLSL of :func:`glsl_source`.

    Parameters
    ----------
    gm : a version-3 :class:`GlintsMap` (what ``prefilter bake glints`` and the renderer's cache
        hold; ``"f32"`` and ``"f16"`` also take float maps).
    normal_map : (H, W, 3) the map it was baked from: the direct P-NDF below the finest level
        (``elements`` texture) and the smooth lobe's moments; None: neither.
    codes : one of :data:`CODE_FORMATS`.
    limits : WebGL2 limits overriding :data:`WEBGL2_LIMITS` (a browser's actual values).
    intrinsic_roughness : of the direct P-NDF (default: the bake's ``settings``, as the
        renderer's surface).

    Returns
    -------
    dict with ``textures``: name -> ``{"data": flat array, "format": WebGL internal format,
    "shape": (width, height, layers)}`` and ``params``: the uniforms (JSON-able).
    """
    if not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.load), got "
                             f"{type(gm).__name__}")
    if codes not in CODE_FORMATS:
        raise PrefilterError(f"codes: expected one of {CODE_FORMATS}, got {codes!r}")
    pyr = gm.pyramid
    if pyr.n_levels > MAX_LEVELS:
        raise PrefilterError(f"gm: {pyr.n_levels} pyramid levels, the GLSL holds at most "
                             f"MAX_LEVELS = {MAX_LEVELS}")
    pa, pb, (cq, wsc, fa, fb), meta, index, _ = packed(gm)
    B = gm.block
    M = wsc.shape[0]
    meta = np.asarray(meta)
    if meta.shape[0] and int(meta[:, 0].max()) > SUM_SIZE:
        raise PrefilterError(f"gm: a CP group of rank {int(meta[:, 0].max())}, the GLSL sums at "
                             f"most SUM_SIZE = {SUM_SIZE} components of a group")
    ia = _components(meta, M, B)
    Fa = fa.ravel()[ia].astype(np.float64)  # (M, B)
    Fb = fb.ravel()[ia].astype(np.float64)
    W = np.asarray(wsc, np.float64).copy()
    Ct, meta_gpu, index_gpu = _code_texels(cq, meta, gm.block_index, gm.image_cell,
                                           gm.resolution // B)
    Cv = Ct.astype(np.float64)
    if codes == "f32":
        tex = {"fa": (fa.ravel(), "R32F"), "fb": (fb.ravel(), "R32F"),
               "pa": (pa.ravel(), "R32F"), "pb": (pb.ravel(), "R32F"), "c": (Cv, "RGBA32F")}
    elif codes == "f16":
        sa, sb = Fa.sum(1), Fb.sum(1)
        na = np.where(sa > 0, sa, 1.0)
        nb_ = np.where(sb > 0, sb, 1.0)
        W *= na * nb_
        flat = np.empty(M * B)
        tex = {}
        for name, F, s in (("a", Fa, na), ("b", Fb, nb_)):
            flat[ia] = F / s[:, None]
            tex["f" + name] = (flat.copy(), "R16F")
            tex["p" + name] = (_prefix_layout(F / s[:, None], meta, B), "R16F")
        tex["c"] = (Cv, "RGBA16F")
    else:
        if gm.codes is None:
            raise PrefilterError("codes: 'u8' needs a map with stored codes (version 3), got a "
                                 "float map")
        tex = {}
        flat = np.empty(M * B)
        for name, F in (("a", Fa), ("b", Fb)):
            mx = F.max(axis=1)
            mx = np.where(mx > 0, mx, 1.0)
            q8 = np.rint(255.0 * F / mx[:, None])
            W *= mx
            flat[ia] = q8
            tex["f" + name] = (flat.astype(np.uint8), "R8")
            tex["p" + name] = (_prefix_layout(q8 / 255.0, meta, B), "R32F")
        Qc = code_levels(np.asarray(cq).dtype)
        tex["c"] = (np.rint(Cv * 255.0 / Qc).astype(np.uint8), "RGBA8")
        W *= Qc
    tex["w"] = (W, "R32F")
    tex["meta"] = (meta_gpu.astype(np.int32), "RGBA32I")
    tex["index"] = (index_gpu.astype(np.int32).ravel(), "R32I")
    tex["cell"] = (np.asarray(gm.image_cell, np.int32), "R32I")
    sr = float(gm.header.get("settings", {}).get("intrinsic_roughness", 0.005)
               if intrinsic_roughness is None else intrinsic_roughness)
    params = {
        "codes": codes, "resolution": gm.resolution, "block": B, "nb": gm.resolution // B,
        "lo": -gm.support, "pitch": 2.0 * gm.support / gm.resolution,
        "map": [pyr.height, pyr.width], "n_levels": pyr.n_levels,
        "offsets": [int(x) for x in pyr.offsets[:-1]],
        "shapes": [list(pyr.shape(lv)) for lv in range(pyr.n_levels)],
        "sigmas": [pyr.sigma(lv) for lv in range(pyr.n_levels)],
        "strides": [float(pyr.stride(lv)) for lv in range(pyr.n_levels)],
        "sigma_min": resample_min_sigma(pyr), "intrinsic_roughness": sr,
        "direct": normal_map is not None,
    }
    if normal_map is not None:
        s_el, J = elements(normal_map)
        if s_el.shape[:2] != (pyr.height, pyr.width):
            raise PrefilterError(f"normal_map: expected the {pyr.height} x {pyr.width} map the "
                                 f"glints map was baked from, got {s_el.shape[:2]}")
        el = np.zeros(s_el.shape[:2] + (2, 4))
        el[..., 0, :2] = s_el
        el[..., 0, 2] = np.sqrt(np.sum(J * J, axis=(-2, -1)))
        el[..., 1, :] = J.reshape(J.shape[:2] + (4,))
        tex["elements"] = (el.reshape(-1, 4), "RGBA32F")
        params["moments"] = slope_moments(normal_map, sr)
    out = {}
    for name, (data, fmt) in tex.items():
        n = data.shape[0]
        shape = texture_shape(n, name, limits)
        dt = {"R32F": np.float32, "R16F": np.float16, "R8": np.uint8, "R32I": np.int32,
              "RGBA32I": np.int32, "RGBA32F": np.float32, "RGBA16F": np.float16,
              "RGBA8": np.uint8}[fmt]
        chans = 4 if fmt.startswith("RGBA") else 1
        full = np.zeros((shape[0] * shape[1] * shape[2], chans), dt)
        full[:n] = np.asarray(data).reshape(n, chans)
        out[name] = {"data": full.reshape(-1), "format": fmt, "shape": shape}
    # every value of a flat index fits int32: the largest is the c index
    params["textures"] = {k: list(v["shape"]) for k, v in out.items()}
    return {"textures": out, "params": params}


def export_surface(surf, *, codes: str = "f32", limits: dict | None = None) -> dict:
    """:func:`export_gpu` of a :class:`~prefilter.glints.surface.GlintSurface` (what the
    ``glints`` method shades with: :func:`prefilter.glints.render.baked_surface`), with its
    normal map and the model's intrinsic roughness."""
    if surf.gm is None:
        raise PrefilterError("surf: expected a surface with a compressed map, got a direct-only "
                             "surface")
    return export_gpu(surf.gm, surf.normal_map, codes=codes, limits=limits,
                      intrinsic_roughness=surf.intrinsic_roughness)


def write_gpu(export: dict, out_dir, prefix: str = "glints") -> dict:
    """Write :func:`export_gpu`'s textures as raw little-endian ``.bin`` files
    (``<prefix>_<name>.bin``) into ``out_dir``; returns the manifest entry: ``params`` with
    ``files`` (texture name -> ``{"file", "format", "shape"}``)."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    files = {}
    for name, t in export["textures"].items():
        fn = f"{prefix}_{name}.bin"
        with atomic_path(d / fn) as tmp:
            tmp.write_bytes(np.ascontiguousarray(t["data"]).astype(
                t["data"].dtype.newbyteorder("<")).tobytes())
        files[name] = {"file": fn, "format": t["format"], "shape": list(t["shape"])}
    return dict(export["params"], files=files)


def glsl_source() -> str:
    """The glints GLSL (GLSL ES 3.00): the constants shared with Python, then the snippets of
    :data:`GLSL_FILES` (texture access, point and range queries with footprint level selection
    and resampling, direct P-NDF fallback, glint BRDF)."""
    head = "\n".join([
        "// prefilter.glints.gpu: constants of the Python implementation",
        f"#define GLT_MAX_LEVELS {MAX_LEVELS}",
        f"#define GLT_SLOTS {SUM_SLOTS}",
        f"#define GLT_SUM_SIZE {SUM_SIZE}",
        f"#define GLT_MAX_RECTS {MAX_RECTS}",
        f"const float GLT_RESAMPLE_TRUNCATION = {RESAMPLE_TRUNCATION!r};",
        f"const float GLT_RESAMPLE_Q_MIN = {RESAMPLE_Q_MIN!r};",
        f"const float GLT_FALLBACK_TRUNCATION = {FALLBACK_TRUNCATION!r};",
        f"const float GLT_SIGMA_H = {SIGMA_H!r};",
        f"const float GLT_PI = {math.pi!r};",
    ])
    return "\n".join([head] + [(GLSL_DIR / f).read_text() for f in GLSL_FILES])

