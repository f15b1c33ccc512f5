"""The ``ltc-multiscale`` render method (Tao et al. 2021, section 3.1 pipeline).

Per shading sample: the normal map's *unnormalised* average over the pixel footprint (the mip
level chosen by the footprint, trilinear) -> its length ``r`` -> ``alpha_meso(r)`` (eq. 4
inverted) -> ``alpha_total(alpha_micro, alpha_meso)`` (eqs. 6-7) -> the isotropic LTC table at
``alpha_total`` with the renormalised mean normal as shading normal. Everything else (lights,
diffuse, Fresnel, the view clamp) is :func:`prefilter.ltc.shading.shade_ltc`, so the only
difference from the ``ltc`` method is the roughness.

Height-mapped materials carry slope moments, not normals; they are shaded as by ``ltc``
(``alpha_meso = 0``).

Variants (``params={"footprint": ...}``, :data:`FOOTPRINTS`): ``"fit"`` (default) the exact
inverse of eq. 4, our refit of eq. 7 and our footprint read (:data:`LOD_BIAS`, :data:`TAPS`);
``"paper"`` the paper's eqs. 5 and 7 as published on the isotropic mip level; ``"mrl"`` the exact
inverse of eq. 4 and mean-resultant-length matching on the isotropic mip level.

With quad lights only (and the isotropic footprint) the method runs the ``ltc`` method's fused
Numba pass (:func:`prefilter.ltc.render.render_ltc_fused`) with this method's normal-map read
(:func:`normal_read`) and roughness rows (:func:`multiscale_roughness`,
:mod:`prefilter.multiscale.kernels`): the same formulas, ``alpha_meso`` interpolated in the same
table as :func:`prefilter.multiscale.alpha_meso`. :func:`multiscale_attributes` and the NumPy
shader remain the general path (point, directional or textured lights, the anisotropic
footprint) and the reference the fused path is tested against.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.ltc.lighttex import shade_ltc_textured
from prefilter.ltc.render import render_ltc_fused
from prefilter.ltc.table import as_table
from prefilter.render.driver import (footprint_lookup, render_samples, shading_frame,
                                     surface_attributes)
from prefilter.multiscale.convolution import _alpha_total
from prefilter.multiscale.meso import R_COSINE, _alpha_from_r, _mrl, _paper_eq5
from prefilter.render.lighttex import split_lights
from prefilter.validation import as_positive_int

__all__ = ["FOOTPRINTS", "LOD_BIAS", "LOD_BIAS_START", "MESO_TABLE_SIZE", "TAPS", "TAPS_BELOW",
           "TAPS_RATIO", "footprint_read", "meso_table", "multiscale_attributes",
           "multiscale_roughness", "normal_read", "render_multiscale", "taps_lookup"]

#: The ``footprint`` variants of the method: ``(meso, total, our footprint read)`` per name
#: (:func:`prefilter.multiscale.alpha_meso` and :func:`prefilter.multiscale.alpha_total`
#: variants; the read of :data:`LOD_BIAS` / :data:`TAPS` or the paper's isotropic mip level).
FOOTPRINTS = {"fit": ("exact", "fit", True), "paper": ("paper", "paper", False),
              "mrl": ("exact", "mrl", False)}

#: Nodes of the compiled shader's ``alpha_meso`` table, uniform in ``x = sqrt(3 (1 - r))``
#: (the nodes of :func:`prefilter.multiscale.alpha_meso`'s own interpolant, so the fused path
#: reproduces it; 32 KiB).
MESO_TABLE_SIZE = 4097

_MESO_TAB = None


def meso_table() -> np.ndarray:
    """``alpha_meso`` (exact inverse of Tao et al. 2021 eq. 4) at ``x = linspace(0, 1,
    MESO_TABLE_SIZE)``, ``r = 1 - x^2 / 3``: the table the compiled shader interpolates
    linearly in ``x`` (:func:`prefilter.multiscale.kernels.multiscale_alpha`)."""
    global _MESO_TAB
    if _MESO_TAB is None:
        from prefilter.multiscale.meso import alpha_meso

        x = np.linspace(0.0, 1.0, MESO_TABLE_SIZE)
        _MESO_TAB = alpha_meso(np.clip(1.0 - x * x / 3.0, R_COSINE, 1.0))
        _MESO_TAB.setflags(write=False)
    return _MESO_TAB


def multiscale_roughness(objects, meso: str = "exact", total: str = "fit"):
    """Per-material roughness rows of the compiled shader
    (:func:`prefilter.multiscale.kernels.multiscale_samples_kernel`): ``(rows (K, RGH_WIDTH),
    meso_tab)``, or ``None`` for a combination it does not implement (mean-resultant-length
    matching needs the exact inverse)."""
    from prefilter.multiscale import kernels as kn
    from prefilter.multiscale.convolution import FIT_COEFFS, PAPER_EQ7

    modes = {"fit": kn.ROUGH_FIT, "paper": kn.ROUGH_EQ7, "mrl": kn.ROUGH_MRL}
    if total not in modes or meso not in ("exact", "paper") or (total == "mrl"
                                                                 and meso != "exact"):
        return None
    rows = np.zeros((len(objects), kn.RGH_WIDTH))
    for k, obj in enumerate(objects):
        m = obj.material
        a = min(float(np.sqrt(m.alpha_x * m.alpha_y)), 1.0)
        row = rows[k]
        row[kn.RGH_MODE] = modes[total]
        row[kn.RGH_MESO] = kn.MESO_TABLE if meso == "exact" else kn.MESO_EQ5
        row[kn.RGH_ALPHA] = a
        row[kn.RGH_COEF:kn.RGH_COEF + 4] = FIT_COEFFS if total == "fit" else PAPER_EQ7
        row[kn.RGH_MRL] = float(_mrl(np.array(a)))
    return rows, meso_table()


def normal_read(objects, lod_bias: float = 0.0, lod_bias_start=None, taps: int = 0,
                taps_below: float = 4.0, taps_ratio: float = 1.5,
                taps_normalize: bool = False):
    """The fused shader's normal-map read per material ``(K, READ_WIDTH)``
    (:func:`prefilter.render.kernels.surface_sample`), or ``None`` for settings it does not
    implement; the arguments as :func:`multiscale_attributes`."""
    from prefilter.render import kernels as kn

    ramp = lod_bias_start is not None
    if ramp and lod_bias_start < 0:
        return None  # the kernel adds the ramped bias in LOD: exact for start >= 0 only
    read = np.zeros((len(objects), kn.READ_WIDTH))
    read[:, kn.READ_SCALE] = 1.0 if ramp else 2.0 ** lod_bias
    read[:, kn.READ_BIAS] = lod_bias
    read[:, kn.READ_RAMP] = ramp
    read[:, kn.READ_START] = float(lod_bias_start) if ramp else 0.0
    read[:, kn.READ_TAPS] = taps
    read[:, kn.READ_TAPS_BELOW] = taps_below
    read[:, kn.READ_TAPS_RATIO] = taps_ratio
    read[:, kn.READ_TAPS_NORM] = bool(taps_normalize)
    return read


def _taps_args(taps, below, ratio) -> tuple[int, float, float]:
    """Validated ``(taps, taps_below, taps_ratio)`` of the anisotropic-taps option."""
    taps = as_positive_int(taps, "taps", lo=0)
    try:
        below, ratio = float(below), float(ratio)
    except (TypeError, ValueError):
        raise PrefilterError(f"taps_below, taps_ratio: expected numbers, got {below!r}, "
                             f"{ratio!r}") from None
    if not below >= 0.0:  # inf (every footprint) is allowed, NaN is not
        raise PrefilterError(f"taps_below: expected a number >= 0 (texels), got {below!r}")
    if not ratio >= 1.0:
        raise PrefilterError(f"taps_ratio: expected a number >= 1 (axis ratio), got {ratio!r}")
    return taps, below, ratio


def _bias_scale(dudv, shape, lod_bias: float, lod_bias_start) -> np.ndarray:
    """Footprint scale ``2^bias`` per sample ``(N, 1, 1)`` (or a scalar for a constant bias)."""
    if lod_bias_start is None:
        return 2.0 ** lod_bias
    from prefilter.texture.mip import footprint_axes

    major = footprint_axes(dudv, shape)[0]
    lod = np.log2(np.maximum(major, 1.0))
    return (2.0 ** np.clip(lod - lod_bias_start, 0.0, lod_bias))[:, None, None]


def _alpha_meso_fast(r: np.ndarray, variant: str) -> np.ndarray:
    # r comes from averages of unit normals, so it is in [0, 1] without validation
    if variant == "paper":
        return np.clip(_paper_eq5(np.clip(r, R_COSINE, 1.0)), 0.0, 1.0)
    return _alpha_from_r(r)


def footprint_read(chain, uv, dudv, anisotropic: bool, max_aniso: int = 8) -> np.ndarray:
    """The footprint's average ``(N, C)`` of a mip chain: one isotropic trilinear tap (the
    driver's compiled :func:`prefilter.render.driver.footprint_lookup`) or, ``anisotropic``,
    up to ``max_aniso`` taps along the major axis (``MipChain.lookup_footprint``)."""
    if anisotropic:
        return chain.lookup_footprint(uv, dudv, anisotropic=True, max_aniso=max_aniso)
    return footprint_lookup(chain, uv, dudv)


def taps_lookup(chain, uv, dudv, taps: int, below: float = 4.0, ratio: float = 1.5,
                lod_bias: float = 0.0, lod_bias_start=None,
                normalize: bool = False) -> np.ndarray:
    """The normal-map read of the fused shader with anisotropic taps (NumPy twin of
    ``kernels.ltc_samples_kernel``'s lookup). Footprints whose major axis is below ``below``
    texels and longer than ``ratio`` times the minor one: the mean of
    ``n = clip(ceil(major / minor), 2, taps)`` unnormalised trilinear taps spread over the major
    axis, at the LOD of ``max(minor, major / n)`` (anisotropic filtering as GPUs do it);
    elsewhere the single isotropic tap at the major axis' LOD. ``lod_bias`` / ``lod_bias_start``
    as :func:`multiscale_attributes` (the ramped bias is added to both LODs). ``normalize``:
    below LOD 1 each tap's level-0 bilinear read is renormalised (first three channels) before
    the blend with level 1 (bilinear blends of unit texels are shorter than the surface's
    spread of normals).

    Parameters
    ----------
    chain : MipChain (level 0 ``(H, W, C)``)
    uv : numpy.ndarray, shape (N, 2)
    dudv : numpy.ndarray, shape (N, 2, 2)

    Returns
    -------
    numpy.ndarray, shape (N, C)
    """
    from prefilter.texture.mip import footprint_axes

    h, w = chain.levels[0].shape[:2]
    major, minor, direction = footprint_axes(dudv, (h, w))
    ramp = lod_bias_start is not None
    ns = 1.0 if ramp else 2.0 ** lod_bias
    lod = np.log2(np.maximum(ns * major, 1.0))
    bias = np.clip(lod - lod_bias_start, 0.0, lod_bias) if ramp else np.zeros_like(lod)
    out = chain.lookup(uv, lod + bias)
    use = (taps >= 2) & (major < below) & (major > ratio * minor)
    with np.errstate(divide="ignore"):
        n = np.clip(np.ceil(major / np.maximum(minor, 1e-300)), 2, max(taps, 2)).astype(np.int64)
    lod_t = np.log2(np.maximum(ns * np.maximum(minor, major / n), 1.0)) + bias
    axis_uv = direction * (major[:, None] / np.array([w, h], float))
    for k in np.unique(n[use]):
        m = use & (n == k)
        acc = 0.0
        lm = np.clip(lod_t[m], 0.0, chain.n_levels - 1)[:, None]
        for i in range(k):
            p = uv[m] + ((i + 0.5) / k - 0.5) * axis_uv[m]
            tap = chain.lookup(p, lod_t[m])
            if normalize and chain.n_levels > 1:
                low = (lm < 1.0)[:, 0]
                n0 = chain.lookup(p[low], 0.0)
                ln = np.linalg.norm(n0[:, :3], axis=-1, keepdims=True)
                n0 = n0 / np.where(ln > 0.0, ln, 1.0)
                tap[low] = n0 * (1.0 - lm[low]) + chain.lookup(p[low], 1.0) * lm[low]
            acc = acc + tap / k
        out[m] = acc
    return out


def _box_lookup(chain, uv, dudv, taps: int) -> np.ndarray:
    """Mean ``(N, 3)`` of ``taps^2`` *normalised* level-0 bilinear normals on a regular grid over
    the pixel footprint (the parallelogram spanned by ``dudv[:, :, 0]`` and ``dudv[:, :, 1]``):
    the normals the reference shades with, so its length is the footprint's mean resultant
    length without the shortening that interpolating between texels adds."""
    acc = np.zeros((len(uv), 3))
    grid = (np.arange(taps) + 0.5) / taps - 0.5
    for a in grid:
        for b in grid:
            n = chain.lookup(uv + a * dudv[:, :, 0] + b * dudv[:, :, 1], 0.0)[:, :3]
            ln = np.linalg.norm(n, axis=-1, keepdims=True)
            acc += n / np.where(ln > 0.0, ln, 1.0)
    return acc / (taps * taps)


def multiscale_attributes(scene, g, *, meso: str = "exact", total: str = "fit",
                          anisotropic_footprint: bool = False, max_aniso: int = 8,
                          lod_bias: float = 0.0, lod_bias_start=None,
                          box_taps: int = 0, taps: int = 0, taps_below: float = 4.0,
                          taps_ratio: float = 1.5, taps_normalize: bool = False) -> dict:
    """Shading frame, material and multi-scale roughness per hit sample of a flat G-buffer.

    As :func:`prefilter.render.driver.surface_attributes` with ``filtered=True``, plus ``r``
    (N,), the length of the footprint's averaged normal (1 without a normal map), and
    ``alpha`` (N,), the isotropic ``alpha_total`` to shade with. ``meso``: ``alpha_meso`` variant
    (``"exact"`` or ``"paper"``, eq. 5); ``total``: ``alpha_total`` variant (``"fit"``,
    ``"paper"`` (eq. 7) or ``"mrl"``). ``anisotropic_footprint``: average ``ceil(major / minor)``
    (at most ``max_aniso``) taps along the footprint's major axis at the minor axis' LOD
    (``MipChain.lookup_footprint``) instead of one tap at the major axis' LOD; the unnormalised
    normals are averaged over the elongated footprint, so ``r`` sees its true spread.
    ``lod_bias``: the footprint is scaled by ``2^lod_bias`` (levels coarser by ``lod_bias``).
    ``lod_bias_start``: ``None`` (constant bias) or ``s``: the bias ramps in with the footprint,
    ``clip(lod - s, 0, lod_bias)`` with ``lod = log2`` of its major axis in texels, so footprints
    below ``2^s`` texels are read unbiased (distance-dependent stabilisation, see
    ``docs/multiscale.md``).
    ``box_taps``: ``0`` (default, the mip lookup above) or ``k``: the normal map is read as the
    mean of ``k^2`` normalised full-resolution normals over the pixel footprint (a supersampled
    footprint, not a real-time one; it isolates the footprint's error in the study of
    ``docs/multiscale.md``; ``lod_bias`` and the anisotropic footprint do not apply).
    ``taps``: ``0`` (off) or the largest number of anisotropic taps for footprints whose major
    axis is below ``taps_below`` texels and more than ``taps_ratio`` (>= 1) times the minor axis
    (:func:`taps_lookup`, the fused shader's compiled lookup); larger or rounder footprints are
    read as without it. ``taps_normalize``: the taps' level-0 reads are renormalised
    (:func:`taps_lookup`'s ``normalize``).
    """
    box_taps = as_positive_int(box_taps, "box_taps", lo=0)
    taps, taps_below, taps_ratio = _taps_args(taps, taps_below, taps_ratio)

    def surface(mat, uv, dudv, t, b, n):
        if mat.normal_map is None:
            return {"r": 1.0}  # height maps carry slopes, not normals: flat at this scale
        chain = mat.normal_map.mip()
        if box_taps:
            nts = _box_lookup(chain, uv, dudv, box_taps)
        elif taps and not anisotropic_footprint:
            nts = taps_lookup(chain, uv, dudv, taps, taps_below, taps_ratio, lod_bias,
                              lod_bias_start, taps_normalize)
        else:
            scale = _bias_scale(dudv, chain.levels[0].shape[:2], lod_bias, lod_bias_start)
            nts = footprint_read(chain, uv, dudv * scale, anisotropic_footprint, max_aniso)
        r = np.minimum(np.sqrt(np.einsum("ij,ij->i", nts, nts)), 1.0)
        return {**dict(zip("tbn", shading_frame(t, b, n, nts))), "r": r}

    a = surface_attributes(scene, g, surface=surface)
    a["alpha_micro"] = np.sqrt(a["alpha_x"] * a["alpha_y"])
    a["alpha"] = _alpha_total(np.minimum(a["alpha_micro"], 1.0), _alpha_meso_fast(a["r"], meso),
                              total)
    return a


def _render(scene, settings, meso: str, total: str, **footprint) -> np.ndarray:
    name = "ltc-multiscale"
    # textured quad lights: prefiltered light texture lookup (Heitz et al. 2016, section 5.3)
    lights, textured = split_lights(scene, name)
    table = as_table(settings.table)
    if not (lights.points or lights.directionals or textured
            or footprint.get("anisotropic_footprint") or footprint.get("box_taps")):
        # quad lights only: the ``ltc`` method's fused kernel with this roughness
        read = normal_read(scene.objects, footprint.get("lod_bias", 0.0),
                           footprint.get("lod_bias_start"),
                           *_taps_args(footprint.get("taps", 0), footprint.get("taps_below", 4.0),
                                       footprint.get("taps_ratio", 1.5)),
                           footprint.get("taps_normalize", False))
        rough = multiscale_roughness(scene.objects, meso, total)
        if read is not None and rough is not None:
            from prefilter.multiscale.kernels import multiscale_samples_kernel

            image = render_ltc_fused(scene, settings, lights, table, read,
                                     multiscale_samples_kernel, rough, desc=name)
            if image is not None:
                return image

    def shade(g, _u):
        a = multiscale_attributes(scene, g, meso=meso, total=total, **footprint)
        return shade_ltc_textured(g.position, a["t"], a["b"], a["n"], g.view, a["alpha"],
                                  a["base_color"], a["f0"], lights, textured, table)

    return render_samples(scene, settings, shade, stratified=settings.spp > 1, desc=name)


#: The ``ltc-multiscale`` method's footprint: the normal map is read up to two levels coarser,
#: ramping in above 4 texels per pixel (``clip(lod - 2, 0, 2)``): at 16 texels per pixel it halves
#: the flicker of the isotropic LOD for +0.1-2.5 % RMSE, nearer it changes little (measured on
#: three normal maps and two micro roughnesses, ``docs/multiscale.md``).
LOD_BIAS, LOD_BIAS_START = 2.0, 2.0

#: The ``ltc-multiscale`` method's anisotropic taps: footprints below :data:`TAPS_BELOW` texels
#: along the major axis and more than :data:`TAPS_RATIO` times longer than wide are read as up to
#: :data:`TAPS` unnormalised trilinear taps along the major axis at the minor axis' LOD (the
#: near-distance defect of the single isotropic tap; far footprints, where the LOD ramp is on,
#: are read as before, bit for bit). Measured in ``docs/multiscale.md``.
TAPS, TAPS_BELOW, TAPS_RATIO = 4, 4.0, 1.5


def render_multiscale(scene, settings, *, anisotropic_footprint: bool = False,
                      max_aniso: int = 8, lod_bias: float = LOD_BIAS,
                      lod_bias_start=LOD_BIAS_START, box_taps: int = 0,
                      taps: int = TAPS, taps_below: float = TAPS_BELOW,
                      taps_ratio: float = TAPS_RATIO, taps_normalize: bool = False) -> np.ndarray:
    """The ``ltc-multiscale`` method; ``settings.param("footprint")`` picks the variant
    (:data:`FOOTPRINTS`, module docstring).

    ``anisotropic_footprint`` / ``max_aniso`` / ``lod_bias`` / ``lod_bias_start`` /
    ``box_taps`` / ``taps`` / ``taps_below`` / ``taps_ratio`` / ``taps_normalize``: the footprint
    read of the ``"fit"`` variant, see :func:`multiscale_attributes`; the default is
    :data:`LOD_BIAS` levels coarser at most, ramping in from :data:`LOD_BIAS_START`, with
    :data:`TAPS` anisotropic taps below :data:`TAPS_BELOW` texels (``lod_bias=0, taps=0`` is the
    paper's isotropic mip level; all measured in ``docs/multiscale.md``). The ``"paper"`` and
    ``"mrl"`` variants read the paper's isotropic mip level."""
    variant = settings.param("footprint", "fit")
    if variant not in FOOTPRINTS:
        raise PrefilterError(f"footprint: expected one of {', '.join(FOOTPRINTS)}, got "
                             f"{variant!r}")
    meso, total, ours = FOOTPRINTS[variant]
    if not ours:
        return _render(scene, settings, meso, total)
    return _render(scene, settings, meso, total,
                   anisotropic_footprint=anisotropic_footprint, max_aniso=max_aniso,
                   lod_bias=lod_bias, lod_bias_start=lod_bias_start, box_taps=box_taps,
                   taps=taps, taps_below=taps_below, taps_ratio=taps_ratio,
                   taps_normalize=taps_normalize)
