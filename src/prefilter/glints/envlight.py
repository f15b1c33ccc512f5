"""Environment lighting of glints by spherical Gaussians with angular prefiltering (paper sec. 5.4).

The environment is a sum of spherical Gaussians ``L(w) = sum_k mu_k exp(lambda_k (w.p_k - 1))``
(rgb amplitudes ``mu (K, 3)``, sharpness ``lambda (K,)``, unit axes ``p (K, 3)`` in the shading
tangent frame). One estimate per sample: choose a lobe by its energy, draw ``wi`` from it exactly
(pdf ``lambda e^{lambda (w.p - 1)} / (2 pi (1 - e^{-2 lambda}))``), weight by the mixture pdf
(one-sample MIS over the lobes, so the unprefiltered estimator is unbiased).

Prefiltering replaces the NDF point value ``D(h)`` by the **range mean** of the footprint's NDF
image over the square of half-width ``theta_eps / 2`` around ``h_xy``: the light's compact
epsilon-support ``theta_eps = acos(1 + ln(eps / mu) / lambda)`` (equations.md 6; Wang et al.
2009) moves ``wi`` by up to ``theta_eps``, which moves the half vector by half that angle, ~the same
distance in ``s`` near the pole. The estimate is then a blurred (biased) NDF with much less
variance at equal samples (Fig. 11 of the paper); ``eps`` is relative to ``|mu|``.

Axes ``p`` may also be per shading sample, ``(N, K, 3)`` (each sample's tangent frame).
:func:`fit_sg` fits an equirectangular environment image by a fixed set of lobes (Fibonacci axes,
one sharpness, non-negative least squares amplitudes); :func:`equirect_directions` gives the
image's orientation convention (``docs/scenes.md``: row 0 is ``+y``, ``u = 0`` looks towards
``+z``, ``u = 1/4`` towards ``-x``).
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_float_array, as_rng
from prefilter.errors import PrefilterError
from prefilter.microfacet.fresnel import schlick
from prefilter.glints.brdf import glint_ndf, vcavity_g2
from prefilter.glints.query import range_multi, weights
from prefilter.glints.surface import as_surface


#: Pyramid weights of the environment lights' range queries (:func:`shade_sg`): trilinear.
#: Unlike quad lights' it shows no bias here (plane mid, 32 seeds, FLIP vs the matched reference:
#: flakes 0.030 trilinear / 0.033 resampled, gaussian 0.023 / 0.023) and resampling costs 3-4x
#: the frame (benchmarks/study_glints_env_interp.py).
RANGE_INTERP = "trilinear"


def as_lobes(mu, lam, p):
    """Validated SG lobes: amplitudes ``mu (K, 3)`` >= 0, sharpness ``lam (K,)`` > 0 and axes
    ``p (K, 3)`` or per-sample ``(N, K, 3)``, returned as float64 arrays with ``p`` normalised."""
    mu = as_float_array(mu, "mu", ndim_min=2, last_dim=3)
    lam = as_float_array(lam, "lam", ndim_min=1)
    p = as_float_array(p, "p", ndim_min=2, last_dim=3)
    if not (mu.shape[0] == lam.shape[0] == p.shape[-2]) or lam.ndim != 1 or p.ndim > 3:
        raise PrefilterError(f"lam: expected K lobes matching mu {mu.shape} and p {p.shape}, got "
                             f"{lam.shape}")
    if np.any(mu < 0) or np.any(lam <= 0):
        raise PrefilterError("mu, lam: expected amplitudes >= 0 and sharpness > 0")
    return mu, lam, p / np.linalg.norm(p, axis=-1, keepdims=True)


def _dots(w, p):
    """``w.p_k`` ``(..., K)`` for shared axes ``(K, 3)`` or per-sample axes ``(N, K, 3)``."""
    w = np.asarray(w, dtype=np.float64)
    if p.ndim == 2:
        return w @ p.T
    return np.einsum("nc,nkc->nk", w, p)


def sg_eval(w, mu, lam, p) -> np.ndarray:
    """Radiance ``(..., 3)`` of the SG environment at directions ``w (..., 3)``."""
    return _sg_eval(w, *as_lobes(mu, lam, p))


def _sg_eval(w, mu, lam, p):
    e = np.exp(lam * (_dots(w, p) - 1.0))  # (..., K)
    return e @ mu


def sg_energy(lam) -> np.ndarray:
    """``integral exp(lambda (w.p - 1)) dw = 2 pi (1 - e^{-2 lambda}) / lambda``."""
    lam = np.asarray(lam, dtype=np.float64)
    return 2.0 * np.pi * (-np.expm1(-2.0 * lam)) / lam


def eps_support(mu, lam, eps: float = 0.1) -> np.ndarray:
    """Compact epsilon-support angle ``acos(1 + ln(eps) / lambda)`` (``eps`` relative to the
    amplitude; ``pi`` when the lobe never drops below it)."""
    lam = np.asarray(lam, dtype=np.float64)
    return np.arccos(np.clip(1.0 + np.log(eps) / lam, -1.0, 1.0))


def _frame(p):
    t = np.where(np.abs(p[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    t = t - np.sum(t * p, -1, keepdims=True) * p
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return t, np.cross(p, t)


def sample_sg(mu, lam, p, u) -> tuple[np.ndarray, np.ndarray]:
    """Directions ``(N, 3)`` from the lobe mixture (lobe chosen by luminance energy) and their
    mixture pdf ``(N,)``; ``u (N, 3)`` uniforms."""
    return _sample_sg(*as_lobes(mu, lam, p), u)


def sg_light_samples(mu, lam, p, u) -> tuple[np.ndarray, np.ndarray]:
    """``n`` light samples per point from the lobe mixture, as :func:`shade_sg` draws them:
    directions ``(n, N, 3)`` and weights ``L(wi) / (n pdf)`` ``(n, N, 3)`` (0 where the pdf is
    0); ``u (N, 3 n)``: sample ``j`` uses columns ``3 j .. 3 j + 2``. The lobes are validated
    once for all ``n`` samples."""
    mu, lam, p = as_lobes(mu, lam, p)
    u = np.asarray(u, dtype=np.float64)
    ns = u.shape[1] // 3
    wis, wgts = [], []
    for j in range(ns):
        wi, pdf = _sample_sg(mu, lam, p, u[:, 3 * j:3 * j + 3])
        ok = pdf > 0
        wis.append(wi)
        wgts.append(_sg_eval(wi, mu, lam, p)
                    * np.where(ok, 1.0 / (ns * np.where(ok, pdf, 1.0)), 0.0)[:, None])
    return np.stack(wis), np.stack(wgts)


def _lobe_probabilities(wgt) -> np.ndarray:
    """Lobe selection probabilities proportional to ``wgt (K,)``; uniform for a black
    environment (every lobe contributes zero, any choice is exact)."""
    total = wgt.sum()
    return wgt / total if total > 0 else np.full(wgt.shape, 1.0 / wgt.size)


def _sample_sg(mu, lam, p, u):
    u = np.asarray(u, dtype=np.float64)
    wgt = mu.mean(axis=1) * sg_energy(lam)
    P = _lobe_probabilities(wgt)
    k = np.minimum(np.searchsorted(np.cumsum(P), u[:, 0] * 1.0, side="right"), len(P) - 1)
    lk = lam[k]
    # exact inversion of the SG's cosine marginal
    cos = 1.0 + np.log1p(-u[:, 1] * (-np.expm1(-2.0 * lk))) / lk
    cos = np.clip(cos, -1.0, 1.0)
    sin = np.sqrt(np.maximum(1.0 - cos * cos, 0.0))
    phi = 2.0 * np.pi * u[:, 2]
    pk = p[k] if p.ndim == 2 else p[np.arange(len(k)), k]
    t, b = _frame(pk)
    w = (sin * np.cos(phi))[:, None] * t + (sin * np.sin(phi))[:, None] * b + cos[:, None] * pk
    return w, _sg_pdf(w, mu, lam, p)


def sg_pdf(w, mu, lam, p) -> np.ndarray:
    """Mixture pdf of :func:`sample_sg` at ``w (..., 3)``."""
    return _sg_pdf(w, *as_lobes(mu, lam, p))


def _sg_pdf(w, mu, lam, p):
    wgt = mu.mean(axis=1) * sg_energy(lam)
    P = _lobe_probabilities(wgt)
    dens = np.exp(lam * (_dots(w, p) - 1.0)) / sg_energy(lam)
    return dens @ P


def shade_sg(surf, center, sigma_p, wo, mu, lam, p, f0=1.0, *, n_samples: int = 16, rng=0,
             prefilter: bool = True, eps: float = 0.1, u=None, base_color=None,
             fallback_truncation: float | None = None) -> np.ndarray:
    """Specular radiance ``(N, 3)`` of footprints ``(center (N, 2), sigma_p (N,))`` seen from
    ``wo (N, 3)`` (tangent frame) under the SG environment; ``n_samples`` light samples each.

    ``prefilter=True``: the NDF is the range mean over ``h_xy +- theta_eps / 2`` of the chosen
    lobe (needs a compressed map; footprints below its finest level keep the point NDF, which is
    the direct P-NDF there); ``False``: the point NDF of :func:`glint_ndf` (unbiased). ``p`` is
    ``(K, 3)`` or per sample ``(N, K, 3)``. ``u``: optional ``(N, 3 n_samples)`` uniforms (else
    drawn from ``rng``). ``base_color (3,)``: adds the Lambertian term from the same samples.
    ``fallback_truncation``: that of :func:`glint_ndf`'s direct P-NDF (the render's ``glints``
    passes 4 stds: the same values to 3e-8, the fast row kernel)."""
    surf = as_surface(surf)
    mu, lam, p = as_lobes(mu, lam, p)
    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), c.shape[:1])
    wo = np.broadcast_to(as_float_array(wo, "wo", ndim_min=1, last_dim=3), c.shape[:1] + (3,))
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    if prefilter and surf.gm is None:
        raise PrefilterError("surf: prefiltering needs a compressed map (range queries)")
    N = c.shape[0]
    if u is None:
        uu = as_rng(rng).random((N, 3 * n_samples))
    else:
        uu = as_float_array(u, "u")
        if uu.shape != (N, 3 * n_samples) or np.any((uu < 0) | (uu >= 1)):
            raise PrefilterError(f"u: expected uniforms in [0, 1) of shape {(N, 3 * n_samples)}, "
                                 f"got {uu.shape}")
    if p.ndim == 3 and p.shape[0] != N:
        raise PrefilterError(f"p: expected per-sample axes ({N}, K, 3), got {p.shape}")
    out = np.zeros((N, 3))
    half_eps = 0.5 * eps_support(mu, lam, eps)
    wgt = mu.mean(axis=1) * sg_energy(lam)
    cum = np.cumsum(_lobe_probabilities(wgt))
    small = (sp < surf.sigma_min) if surf.normal_map is not None else np.zeros(N, bool)
    if prefilter:
        # the footprints are the same for every sample: their pyramid weights once
        idx, w, _ = weights(surf.gm, c[~small], sp[~small], interp=RANGE_INTERP)
    samples = []
    for j in range(n_samples):
        u = uu[:, 3 * j:3 * j + 3]
        wi, pdf = _sample_sg(mu, lam, p, u)
        k = np.minimum(np.searchsorted(cum, u[:, 0], side="right"), len(cum) - 1)
        h = wo + wi
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        samples.append((wi, pdf, k, h, (wi[:, 2] > 0) & (h[:, 2] > 0) & (pdf > 0)))
    if prefilter:
        # all the samples' squares of a footprint in one call: they share its pyramid taps;
        # samples that contribute 0 anyway (light below the horizon: ~12 %) are not queried
        hs = np.stack([h[~small, :2] for _, _, _, h, _ in samples], 1)  # (n, n_samples, 2)
        r = np.stack([np.maximum(half_eps[k], 1e-6)[~small] for _, _, k, _, _ in samples], 1)
        act = np.stack([ok[~small] for *_, ok in samples], 1)
        means = range_multi(surf.gm, idx, w, hs - r[..., None], hs + r[..., None], act)
    for j, (wi, pdf, k, h, ok) in enumerate(samples):
        if prefilter:
            D = np.empty(N)
            D[~small] = means[:, j]
            if np.any(small):
                D[small] = glint_ndf(surf, c[small], sp[small], h[small, :2],
                                     fallback_truncation=fallback_truncation)
        else:
            D = glint_ndf(surf, c, sp, h[:, :2], fallback_truncation=fallback_truncation)
        G = vcavity_g2(wo, wi, h)
        val = np.where(ok, D * G / (4.0 * np.where(ok, wo[:, 2] * pdf, 1.0)), 0.0)
        L = _sg_eval(wi, mu, lam, p)
        out += val[:, None] * schlick(f0, np.sum(wi * h, -1)[:, None]) * L
        if base_color is not None:
            lam_ok = (wi[:, 2] > 0) & (pdf > 0)
            cosw = np.where(lam_ok, wi[:, 2] / np.where(lam_ok, pdf, 1.0), 0.0)
            out += np.asarray(base_color, dtype=np.float64) / np.pi * L * cosw[:, None]
    return out / n_samples


def equirect_directions(height: int, width: int) -> np.ndarray:
    """Unit world directions ``(H, W, 3)`` of the pixel centres of a scene environment image,
    the convention of ``docs/scenes.md``: ``u = (col + 0.5) / W``, ``v = (row + 0.5) / H``,
    ``d = (-sin(pi v) sin(2 pi u), cos(pi v), sin(pi v) cos(2 pi u))`` (row 0 is the zenith
    ``+y``, ``u = 0`` looks towards ``+z``, ``u = 1/4`` towards ``-x``, the centre towards
    ``-z``), via :data:`prefilter.leadr.envmap.ENV_FROM_WORLD`."""
    from prefilter.leadr.envmap import ENV_FROM_WORLD, texel_directions

    d, _ = texel_directions(int(height), int(width))
    return d @ ENV_FROM_WORLD


def fibonacci_axes(n: int) -> np.ndarray:
    """``n`` nearly uniform unit vectors ``(n, 3)`` (spherical Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([r * np.cos(phi), z, r * np.sin(phi)], -1)


def fit_sg(image, n_lobes: int = 32, *, max_res: int = 64):
    """Spherical-Gaussian fit ``(mu (K, 3), lam (K,), p (K, 3))`` of an equirectangular image
    ``(H, W, C)`` (linear radiance; C = 1 is grey) in world axes (:func:`equirect_directions`).

    Axes on a Fibonacci lattice, one sharpness for all (a lobe falls to 1/2 at half the mean
    axis spacing, so neighbours overlap), amplitudes by non-negative least squares per channel
    on the image box-filtered to at most ``max_res`` columns, weighted by pixel solid angle
    (Tsai and Shih 2006 fit all three; fixed axes keep the fit linear and deterministic)."""
    from scipy.optimize import nnls

    img = as_float_array(image, "image", ndim_min=2)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4) or np.any(img < 0):
        raise PrefilterError(f"image: expected a non-negative (H, W, 1|3|4) image, got {img.shape}")
    img = np.broadcast_to(img[..., :3], img.shape[:2] + (3,)) if img.shape[2] >= 3 else \
        np.repeat(img, 3, axis=2)
    H, W = img.shape[:2]
    f = max(1, W // max_res)
    Hs, Ws = H // f, W // f
    if Hs < 2 or Ws < 2:
        raise PrefilterError(f"image: expected at least 2 x 2 pixels after filtering, got "
                             f"{img.shape}")
    small = img[:Hs * f, :Ws * f].reshape(Hs, f, Ws, f, 3).mean(axis=(1, 3))
    d = equirect_directions(Hs, Ws).reshape(-1, 3)
    sa = (np.sin(np.pi * (np.arange(Hs) + 0.5) / Hs)[:, None] * np.ones(Ws)).ravel()
    p = fibonacci_axes(int(n_lobes))
    spacing = np.sqrt(4.0 * np.pi / len(p))
    lam = np.full(len(p), np.log(2.0) / (1.0 - np.cos(0.5 * spacing)))
    A = np.exp(lam * (d @ p.T - 1.0)) * np.sqrt(sa)[:, None]
    mu = np.stack([nnls(A, small.reshape(-1, 3)[:, ch] * np.sqrt(sa), maxiter=50 * len(p))[0]
                   for ch in range(3)], -1)
    return mu, lam, p
