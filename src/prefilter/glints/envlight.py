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
"""

from __future__ import annotations

import numpy as np

from prefilter._validate import as_float_array, as_rng
from prefilter.errors import PrefilterError
from prefilter.glints.brdf import _as_surface, glint_ndf, schlick, vcavity_g2
from prefilter.glints.query import range_mean


def _lobes(mu, lam, p):
    mu = as_float_array(mu, "mu", ndim_min=2, last_dim=3)
    lam = as_float_array(lam, "lam", ndim_min=1)
    p = as_float_array(p, "p", ndim_min=2, last_dim=3)
    if not (mu.shape[0] == lam.shape[0] == p.shape[0]) or lam.ndim != 1:
        raise PrefilterError(f"lam: expected K lobes matching mu {mu.shape} and p {p.shape}, got "
                             f"{lam.shape}")
    if np.any(mu < 0) or np.any(lam <= 0):
        raise PrefilterError("mu, lam: expected amplitudes >= 0 and sharpness > 0")
    return mu, lam, p / np.linalg.norm(p, axis=-1, keepdims=True)


def sg_eval(w, mu, lam, p) -> np.ndarray:
    """Radiance ``(..., 3)`` of the SG environment at directions ``w (..., 3)``."""
    mu, lam, p = _lobes(mu, lam, p)
    w = np.asarray(w, dtype=np.float64)
    e = np.exp(lam * (w @ p.T - 1.0))  # (..., K)
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
    mu, lam, p = _lobes(mu, lam, p)
    u = np.asarray(u, dtype=np.float64)
    wgt = mu.mean(axis=1) * sg_energy(lam)
    P = wgt / wgt.sum()
    k = np.minimum(np.searchsorted(np.cumsum(P), u[:, 0] * 1.0, side="right"), len(P) - 1)
    lk = lam[k]
    # exact inversion of the SG's cosine marginal
    cos = 1.0 + np.log1p(-u[:, 1] * (-np.expm1(-2.0 * lk))) / lk
    cos = np.clip(cos, -1.0, 1.0)
    sin = np.sqrt(np.maximum(1.0 - cos * cos, 0.0))
    phi = 2.0 * np.pi * u[:, 2]
    t, b = _frame(p[k])
    w = (sin * np.cos(phi))[:, None] * t + (sin * np.sin(phi))[:, None] * b + cos[:, None] * p[k]
    return w, sg_pdf(w, mu, lam, p)


def sg_pdf(w, mu, lam, p) -> np.ndarray:
    """Mixture pdf of :func:`sample_sg` at ``w (..., 3)``."""
    mu, lam, p = _lobes(mu, lam, p)
    wgt = mu.mean(axis=1) * sg_energy(lam)
    P = wgt / wgt.sum()
    dens = np.exp(lam * (np.asarray(w) @ p.T - 1.0)) / sg_energy(lam)
    return dens @ P


def shade_sg(surf, center, sigma_p, wo, mu, lam, p, f0=1.0, *, n_samples: int = 16, rng=0,
             prefilter: bool = True, eps: float = 0.1) -> np.ndarray:
    """Specular radiance ``(N, 3)`` of footprints ``(center (N, 2), sigma_p (N,))`` seen from
    ``wo (N, 3)`` (tangent frame) under the SG environment; ``n_samples`` light samples each.

    ``prefilter=True``: the NDF is the range mean over ``h_xy +- theta_eps / 2`` of the chosen
    lobe (needs a compressed map); ``False``: the point NDF of :func:`glint_ndf` (unbiased)."""
    surf = _as_surface(surf)
    mu, lam, p = _lobes(mu, lam, p)
    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), c.shape[:1])
    wo = np.broadcast_to(as_float_array(wo, "wo", ndim_min=1, last_dim=3), c.shape[:1] + (3,))
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    if prefilter and surf.gm is None:
        raise PrefilterError("surf: prefiltering needs a compressed map (range queries)")
    gen = as_rng(rng)
    N = c.shape[0]
    out = np.zeros((N, 3))
    half_eps = 0.5 * eps_support(mu, lam, eps)
    wgt = mu.mean(axis=1) * sg_energy(lam)
    cum = np.cumsum(wgt / wgt.sum())
    for _ in range(n_samples):
        u = gen.random((N, 3))
        wi, pdf = sample_sg(mu, lam, p, u)
        k = np.minimum(np.searchsorted(cum, u[:, 0], side="right"), len(cum) - 1)
        h = wo + wi
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        ok = (wi[:, 2] > 0) & (h[:, 2] > 0) & (pdf > 0)
        if prefilter:
            r = np.maximum(half_eps[k], 1e-6)[:, None]
            D = range_mean(surf.gm, c, sp, h[:, :2] - r, h[:, :2] + r)
        else:
            D = glint_ndf(surf, c, sp, h[:, :2])
        G = vcavity_g2(wo, wi, h)
        val = np.where(ok, D * G / (4.0 * wo[:, 2] * np.where(ok, pdf, 1.0)), 0.0)
        out += val[:, None] * schlick(f0, np.sum(wi * h, -1)) * sg_eval(wi, mu, lam, p)
    return out / n_samples
