"""RGB glint lobe of a baked wave-optics map: point and range queries, BRDF, sampling, pdf.

Each channel is a compressed NDF pyramid (:mod:`prefilter.glints.wave.bake`); a query asks the
three (:func:`prefilter.glints.query.point` / ``range_mean``). Footprints smaller than the
coherence area (``sigma_p < sigma0``, the level-0 footprint) see the coherence area's pattern:
the pyramid's clamp (:func:`prefilter.glints.pyramid.interp_weights`).

Sampling (glint paper sec. 5.2, "the grayscale NDF image"): the luminance NDF
``D_Y = sum_c Y_c D_c`` (``Y_c``: :data:`prefilter.glints.wave.cmf.LUMINANCE`) is sampled exactly
as the mixture of the channels' hierarchical samplers
(:func:`prefilter.glints.sample.sample_s`), channel ``c`` chosen with probability
``Y_c M_c / sum_c' Y_c' M_c'`` (``M_c`` the mass of its image), so the density is
``D_Y(s) / sum_c Y_c M_c`` (:func:`pdf_s`); a sample's weight is per channel.
"""

from __future__ import annotations

import numpy as np

from prefilter.glints.brdf import brdf_cos_from_ndf, half
from prefilter.glints.query import point, range_mean
from prefilter.glints.sample import half_from_s, mass
from prefilter.glints.wave.bake import WaveMap
from prefilter.glints.wave.cmf import LUMINANCE
from prefilter.errors import PrefilterError
from prefilter.validation import as_directions, as_float_array, as_rng

#: pyramid weights and NDF lookup of the render (as the geometric ``glints`` method's)
INTERP = "resample"
BILINEAR = True


def _check(wm):
    if not isinstance(wm, WaveMap):
        raise PrefilterError(f"wm: expected a WaveMap (prefilter.glints.wave.load_wave), got "
                             f"{type(wm).__name__}")


def point_rgb(wm: WaveMap, center, sigma_p, s, *, interp: str = INTERP,
              bilinear: bool = BILINEAR) -> np.ndarray:
    """RGB NDF ``(..., 3)`` (densities w.r.t. ``s``) of footprints ``center (..., 2)``,
    ``sigma_p (...)`` at ``s (..., 2)``."""
    _check(wm)
    return np.stack([point(gm, center, sigma_p, s, interp=interp, bilinear=bilinear)
                     for gm in wm.channels], axis=-1)


def range_rgb(wm: WaveMap, center, sigma_p, s_min, s_max, *,
              interp: str = "trilinear") -> np.ndarray:
    """Mean RGB NDF ``(..., 3)`` over the rectangles ``[s_min, s_max]`` of ``s``."""
    _check(wm)
    return np.stack([range_mean(gm, center, sigma_p, s_min, s_max, interp=interp)
                     for gm in wm.channels], axis=-1)


def brdf_cos_rgb(wm: WaveMap, center, sigma_p, wo, wi, f0=1.0, *, interp: str = INTERP,
                 bilinear: bool = BILINEAR) -> np.ndarray:
    """Cosine-weighted RGB glint BRDF ``(..., 3)``: ``F G D_c(h_xy) / (4 wo_z)`` per channel
    (paper eq. 1; V-cavity ``G``, Schlick ``F`` with ``f0`` scalar or ``(..., 3)``).
    ``interp="trilinear", bilinear=False`` evaluates the images :func:`sample_s` draws from."""
    wo = as_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    f0 = np.broadcast_to(np.atleast_1d(as_float_array(f0, "f0")), (3,) if np.ndim(f0) == 0
                         else np.shape(f0))
    h = half(wo, wi)
    D = point_rgb(wm, center, sigma_p, h[..., :2], interp=interp, bilinear=bilinear)
    return np.stack([brdf_cos_from_ndf(wo, wi, h, D[..., c], f0[..., c:c + 1])[..., 0]
                     for c in range(3)], axis=-1)


def masses(wm: WaveMap, center, sigma_p) -> np.ndarray:
    """Masses ``(..., 3)`` of the footprints' channel images (what the sampler normalises)."""
    _check(wm)
    return np.stack([mass(gm, center, sigma_p) for gm in wm.channels], axis=-1)


def pdf_s(wm: WaveMap, center, sigma_p, s) -> np.ndarray:
    """Density ``(...)`` w.r.t. ``s`` of :func:`sample_s`: ``sum_c Y_c D_c(s) / sum_c Y_c M_c``
    (pixel values, as the sampler draws them)."""
    D = point_rgb(wm, center, sigma_p, s, interp="trilinear", bilinear=False)
    M = masses(wm, center, sigma_p) @ LUMINANCE
    num = D @ LUMINANCE
    return np.where(M > 0, num / np.where(M > 0, M, 1.0), 0.0)


def sample_s(wm: WaveMap, center, sigma_p, rng=0):
    """Projected half vectors ``s (N, 2)`` distributed as the luminance NDF of footprints
    ``center (N, 2)``, ``sigma_p (N,)``, and their density (:func:`pdf_s`)."""
    from prefilter.glints import sample as gsample

    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), c.shape[:-1])
    gen = as_rng(rng)
    M = masses(wm, c, sp) * LUMINANCE
    tot = M.sum(-1)
    cdf = np.cumsum(M, -1) / np.where(tot > 0, tot, 1.0)[:, None]
    ch = np.minimum((gen.random(len(c))[:, None] >= cdf).sum(-1), 2)
    s = np.zeros(c.shape)
    for k, gm in enumerate(wm.channels):
        sel = np.flatnonzero(ch == k)
        if sel.size:
            s[sel] = gsample.sample_s(gm, c[sel], sp[sel], gen)[0]
    return s, pdf_s(wm, c, sp, s)


def sample_wi(wm: WaveMap, center, sigma_p, wo, rng=0):
    """Light directions ``wi = 2 (wo.m) m - wo`` with ``m`` from :func:`sample_s`; returns
    ``wi (N, 3)`` and the pdf w.r.t. solid angle ``p_s(s) m_z / (4 wo.m)`` (0 below the
    horizon)."""
    wo = as_directions(wo, "wo")
    s, ps = sample_s(wm, center, sigma_p, rng)
    m = half_from_s(s)
    wom = np.sum(wo * m, -1)
    wi = 2.0 * wom[:, None] * m - wo
    ok = (wom > 0) & (wi[:, 2] > 0) & (ps > 0)
    pdf = np.where(ok, ps * m[:, 2] / (4.0 * np.where(ok, wom, 1.0)), 0.0)
    return wi, pdf
