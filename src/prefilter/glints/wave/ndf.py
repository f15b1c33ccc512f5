"""Wave-optics NDF images of Gaussian footprints (Yan et al. 2018, as the glint paper's sec. 4.1).

The field scattered by a patch of heightfield ``h`` lit through a Gaussian window
``G(x) = exp(-|x - c|^2 / (4 sigma_p^2))`` is, in the Harvey-Shack form with ``q = k (w_i + w_o)``
and ``k = 2 pi / lambda`` (Yan et al. 2018, eqs. 5-7),

    A(s) = integral G(x) exp(i 2k (s . x + h(x))) dx,

written here in the projected half vector ``s`` with the paraxial ``q_xy = 2k s``,
``q_z = 2k`` (the retro-reflection, ``w_i = w_o``, form of the phase). Its intensity, normalised by
Parseval (``integral |A|^2 ds = (lambda / 2)^2 integral G^2 dx``), is a density in ``s``:

    D_lambda(s) = |A(s)|^2 / ((lambda / 2)^2 integral G^2 dx).

The field's window has std ``sqrt(2) sigma_p`` so that the intensity's, ``G^2``, is the geometric
footprint ``exp(-|x - c|^2 / (2 sigma_p^2))``: the energy of a stationary point scales with
``G^2``, so this is the window whose geometric limit is the P-NDF of the same footprint.

Stationary phase puts the energy where ``s = -grad h``, the projected normal to first order in the
slope: as ``lambda -> 0`` ``D_lambda`` tends to the geometric P-NDF of the same surface (the
mapping's error is ``O(|s|^3)``, 0.5 % of ``s`` at ``|s| = 0.1``). A flat patch gives the window's
pattern, a Gaussian of std ``lambda / (8 pi sigma_p)`` in ``s``.

Coherence: the window of the level-0 footprint (``sigma0`` texels) is the coherence area. A
larger footprint ``sigma_p`` is the incoherent sum of coherence areas around its centre, weighted
by ``N(c'; c, sigma_p^2 - sigma0^2)`` (Yan et al. 2018's footprint of many coherence areas):
this is linear in the footprint like the geometric P-NDF, so the pyramid's filtering
(:mod:`prefilter.glints.pyramid`) builds the coarser levels exactly as for geometric optics.

Numerics: the sum over the band-limited heights resampled ``upsample`` times finer
(:func:`heightfield.upsampled`; fine enough that the spectrum's aliases fall outside the image),
as one matrix product per window and wavelength, ``E_y M E_x^T`` with ``M = G exp(i 2k h)`` and
``E[j, m] = exp(i 2k s_j x_m)``; ``supersample^2`` points per NDF pixel are averaged (pixel means,
as the geometric images).
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.glints.wave.cmf import WAVELENGTHS, spectral_to_rgb
from prefilter.glints.wave.heightfield import Heightfield, gradient, heightfield, upsampled
from prefilter.validation import as_float_array, as_positive_int, check_scalar

#: footprint windows are cut at this many stds (as the geometric ``pndf.TRUNCATION``)
TRUNCATION = 4.0
#: windows per matrix-product batch (memory: a few MB each)
BATCH = 64


def diffraction_std(wavelength: float, sigma_m: float) -> float:
    """Std in ``s`` of a flat patch's pattern for a footprint of std ``sigma_m`` metres (field
    window ``sqrt(2) sigma_m``): ``lambda / (8 pi sigma_m)``."""
    return wavelength / (8.0 * math.pi * sigma_m)


def as_wavelengths(wavelengths) -> np.ndarray:
    lam = as_float_array(wavelengths, "wavelengths", ndim_min=1)
    if lam.ndim != 1 or lam.size == 0 or np.any(lam <= 0):
        raise PrefilterError(f"wavelengths: expected a non-empty 1-D array of positive "
                             f"wavelengths in metres, got {lam!r}")
    return lam


def upsample_factor(hf: Heightfield, wavelength: float, support: float, sigma_m: float) -> int:
    """Resampling factor of the heights that keeps the sum's spectral aliases (spaced
    ``lambda / (2 dx)`` in ``s``) outside ``[-support, support]`` plus the slopes' spread."""
    slope = float(np.abs(gradient(hf)).max())
    reach = support + slope + 6.0 * diffraction_std(wavelength, sigma_m)
    return max(1, math.ceil(2.0 * reach * hf.texel_size / wavelength))


def supersample_factor(wavelength: float, sigma_m: float, pitch: float) -> int:
    """Points per NDF pixel and axis: the pattern's finest detail (the window's diffraction std,
    also the speckle grain) sampled at least twice per std. The mass is then exact to < 1e-8
    (Poisson summation); a pixel mean of a Gaussian of that std to ~1 % (midpoint rule)."""
    return max(1, math.ceil(2.0 * pitch / diffraction_std(wavelength, sigma_m)))


def _windows(hu, f, centers, sigma):
    """Patches ``(N, n, n)`` of upsampled heights around ``centers (N, 2)`` (texels), their field
    window weights ``gy (N, n)``, ``gx (N, n)`` (std ``sqrt(2) sigma``, cut at ``TRUNCATION`` of
    its stds) and the sample offsets ``(n,)`` in texels from the patch's central sample (the
    centres' offsets from those samples are in the weights)."""
    Hu, Wu = hu.shape
    r = int(math.ceil(TRUNCATION * math.sqrt(2.0) * sigma * f))
    m = np.arange(-r, r + 1)
    # nearest upsampled sample to each centre (sample j at 0.5 + j / f)
    jx = np.rint((centers[:, 0] - 0.5) * f).astype(np.int64)
    jy = np.rint((centers[:, 1] - 0.5) * f).astype(np.int64)
    dx = (0.5 + (jx[:, None] + m) / f) - centers[:, 0:1]
    dy = (0.5 + (jy[:, None] + m) / f) - centers[:, 1:2]
    gx = np.exp(-0.25 * (dx / sigma) ** 2)
    gy = np.exp(-0.25 * (dy / sigma) ** 2)
    iy = (jy[:, None] + m) % Hu
    ix = (jx[:, None] + m) % Wu
    patch = hu[iy[:, :, None], ix[:, None, :]]
    return patch, gy, gx, m / f


def spectral_images(hf, center, sigma_p, resolution: int = 64, support: float = 0.25,
                    wavelengths=WAVELENGTHS, *, upsample: int | None = None,
                    supersample: int | None = None) -> np.ndarray:
    """Coherent wave-optics NDF images of Gaussian windows, per wavelength.

    Parameters
    ----------
    hf : Heightfield
    center : (..., 2) window centres in texels; sigma_p : window std in texels (one number).
    resolution, support : NDF image pixels per side and half-width in ``s`` (images as in
        :func:`prefilter.glints.pndf.pndf_image`: row along ``s_y``, column along ``s_x``).
    wavelengths : (L,) metres.
    upsample, supersample : override :func:`upsample_factor` / :func:`supersample_factor`.

    Returns
    -------
    (..., L, R, R) pixel means of ``D_lambda`` (each sums, times the pixel area, to the mass
    inside the square: 1 up to the tails outside it).
    """
    hf = heightfield(hf, 1.0) if not isinstance(hf, Heightfield) else hf
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sigma = check_scalar(sigma_p, "sigma_p", lo=0.0, lo_open=True)
    R = as_positive_int(resolution, "resolution")
    S = check_scalar(support, "support", lo=0.0, hi=1.0, lo_open=True)
    lams = as_wavelengths(wavelengths)
    shape = c.shape[:-1]
    c = c.reshape(-1, 2)
    sig_m = sigma * hf.texel_size
    pitch = 2.0 * S / R
    f = upsample or max(upsample_factor(hf, lam, S, sig_m) for lam in lams)
    hu = upsampled(hf, f)
    out = np.zeros((c.shape[0], lams.size, R, R))
    for li, lam in enumerate(lams):
        k2 = 4.0 * math.pi / lam  # 2k
        q = supersample or supersample_factor(lam, sig_m, pitch)
        s = -S + (np.arange(R * q) + 0.5) * (pitch / q)
        for b0 in range(0, c.shape[0], BATCH):
            patch, gy, gx, off = _windows(hu, f, c[b0:b0 + BATCH], sigma)
            E = np.exp(1j * k2 * hf.texel_size * np.outer(s, off)).astype(np.complex64)
            M = (gy[:, :, None] * gx[:, None, :] * np.exp(1j * k2 * patch)).astype(np.complex64)
            N, n = M.shape[:2]
            # two plain GEMMs over the batch: (Rq, n) (n, N n), then (Rq N, n) (n, Rq)
            T = (E @ M.transpose(1, 0, 2).reshape(n, N * n)).reshape(E.shape[0] * N, n)
            A = (T @ E.T).reshape(E.shape[0], N, E.shape[0]).transpose(1, 0, 2)
            # A (N, Rq, Rq): rows s_y, columns s_x
            I = np.abs(A).astype(np.float64) ** 2
            I = I.reshape(-1, R, q, R, q).mean(axis=(2, 4))
            # |A|^2 dx_u^4 / ((lambda / 2)^2 sum G^2 dx_u^2)
            g2 = (gy ** 2).sum(1) * (gx ** 2).sum(1)
            dxu = hf.texel_size / f
            out[b0:b0 + BATCH, li] = I * (dxu ** 2 / ((lam / 2.0) ** 2 * g2))[:, None, None]
    return out.reshape(shape + (lams.size, R, R))


def rgb_images(hf, center, sigma_p, resolution: int = 64, support: float = 0.25,
               wavelengths=WAVELENGTHS, **kwargs) -> np.ndarray:
    """Coherent wave-optics NDF images ``(..., 3, R, R)`` in linear sRGB
    (:func:`spectral_images` through :func:`prefilter.glints.wave.cmf.spectral_to_rgb`)."""
    return spectral_to_rgb(spectral_images(hf, center, sigma_p, resolution, support,
                                           wavelengths, **kwargs), wavelengths)
