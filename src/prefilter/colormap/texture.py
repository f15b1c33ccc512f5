"""Colour-mapped textures (Heitz et al. 2013, section 4.2): mean and std of the driving function
over a pixel footprint, for tabulated data (moments mips) and for procedural noise (std per LOD).

Tabulated ``f``: a mip chain of ``E[f], E[f^2]`` is looked up over the footprint (trilinear or
anisotropic, :class:`prefilter.texture.mip.MipChain`) and ``sigma_f^2 = E[f^2] - E[f]^2``.

Procedural noise: the footprint mean is the filtered noise itself (a mip of the noise, or any
analytic filtering of it) and the std comes from the generating process: for the Gaussian noise of
:func:`prefilter.texture.procedural.noise`, the variance left inside a level-``L`` footprint is
``sigma^2 - Var_L`` (law of total variance), precomputed per level in a 1D table
(:class:`NoiseStd`) and interpolated linearly in the LOD.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_float_array, check_scalar
from prefilter.colormap.table import as_table
from prefilter.errors import PrefilterError
from prefilter.texture.mip import (
    MipChain,
    footprint_axes,
    lod_from_footprint,
    moment_chain,
    moments_to_stats,
)

__all__ = ["NoiseStd", "filter_noise", "filter_texture", "footprint_stats", "moments_mip",
           "naive_texture", "texture_stats"]


#: Largest magnitude of the values of :func:`moments_mip` (their squares must be finite).
VALUE_MAX = 1e150


def moments_mip(data) -> MipChain:
    """Mip chain of ``E[f], E[f^2]`` of a scalar map ``(H, W)`` (section 4.2): values of magnitude
    at most :data:`VALUE_MAX`, power-of-two sides."""
    a = as_float_array(data, "data", ndim_min=2)
    if a.ndim > 3 or a.shape[0] & (a.shape[0] - 1) or a.shape[1] & (a.shape[1] - 1):
        raise PrefilterError(f"data: expected an (H, W) map with power-of-two sides (mips), got "
                             f"shape {a.shape}")
    if np.any(np.abs(a) > VALUE_MAX):
        raise PrefilterError(f"data: expected values of magnitude <= {VALUE_MAX:g}, got max "
                             f"{np.abs(a).max():.4g}")
    return moment_chain(a)


def footprint_stats(chain: MipChain, uv, dudv, *, anisotropic: bool = False,
                    max_aniso: int = 8):
    """Mean and (co)variance over pixel footprints from a moments mip chain (section 4.2).

    The lookup interpolates the moments; at level 0 that interpolation itself creates a spurious
    variance (``bilerp(f^2) - bilerp(f)^2``: the spread of the four texels under the bilinear
    weights), whereas the function a renderer samples -- the bilinearly interpolated texture --
    barely varies inside a footprint smaller than a texel. That level-0 term is removed with the
    level-0 weight of the trilinear lookup, ``1 - clip(lod, 0, 1)``: magnified footprints get the
    variance 0 (the filtered colour is then the naive one, as it should be) and minified ones are
    unchanged.

    Parameters
    ----------
    chain : MipChain
        Two channels ``E[f], E[f^2]`` or five ``E[x], E[y], E[x^2], E[y^2], E[xy]``
        (:func:`prefilter.texture.mip.moment_chain`).
    uv : array_like, shape (..., 2)
    dudv : array_like, shape (..., 2, 2)

    Returns
    -------
    mean : numpy.ndarray, shape (...) or (..., 2)
    var : numpy.ndarray, shape (...) or (..., 2, 2)
    """
    if not isinstance(chain, MipChain) or chain.shape[2] not in (2, 5):
        raise PrefilterError("chain: expected a moments MipChain with 2 or 5 channels "
                             "(moments_mip / prefilter.texture.mip.moment_chain)")
    h, w = chain.shape[:2]
    m = chain.lookup_footprint(uv, dudv, anisotropic=anisotropic, max_aniso=max_aniso)
    mean, var = moments_to_stats(m)
    lod = lod_from_footprint(dudv, (h, w), anisotropic=anisotropic, max_aniso=max_aniso)
    w0 = 1.0 - np.clip(lod, 0.0, 1.0)
    if np.any(w0 > 0):
        var0 = _level0_interpolation_variance(chain, uv, dudv, anisotropic, max_aniso)
        if var.ndim == mean.ndim:  # scalar data
            var = np.maximum(var - w0 * var0, 0.0)
        else:
            var = _psd(var - w0[..., None, None] * var0)
    return mean, var


def _level0_interpolation_variance(chain, uv, dudv, anisotropic, max_aniso):
    """The level-0 part of the lookup's variance that bilinear interpolation creates, averaged
    over the same taps as :meth:`MipChain.lookup_footprint` (so the spread *between* taps, a
    genuine variation across the footprint, is kept)."""
    uv = np.asarray(uv, dtype=np.float64)
    if not anisotropic:
        return moments_to_stats(chain.lookup(uv, 0.0))[1]
    h, w = chain.shape[:2]
    major, minor, direction = footprint_axes(dudv, (h, w))
    with np.errstate(divide="ignore"):
        taps = np.clip(np.ceil(major / np.maximum(minor, 1e-300)), 1, max_aniso).astype(np.int64)
    axis_uv = direction * (major[..., None] / np.array([w, h], float))
    out = None
    for n in np.unique(taps):  # a loop over tap counts and taps, not pixels
        m = taps == n
        acc = 0.0
        for i in range(n):
            offset = ((i + 0.5) / n - 0.5) * axis_uv[m]
            acc = acc + moments_to_stats(chain.lookup(uv[m] + offset, 0.0))[1] / n
        if out is None:
            out = np.zeros(uv.shape[:-1] + np.shape(acc)[1:])
        out[m] = acc
    return out


def _psd(c: np.ndarray) -> np.ndarray:
    """Clamp 2x2 symmetric matrices to positive semi-definite (eigenvalues >= 0)."""
    p, q, r = c[..., 0, 0], 0.5 * (c[..., 0, 1] + c[..., 1, 0]), c[..., 1, 1]
    mid = 0.5 * (p + r)
    disc = np.sqrt(0.25 * (p - r) ** 2 + q * q)
    l1, l2 = np.maximum(mid + disc, 0.0), np.maximum(mid - disc, 0.0)
    # eigenvector of l1 at angle phi with tan(2 phi) = 2q / (p - r)
    phi = 0.5 * np.arctan2(2.0 * q, p - r)
    cs, sn = np.cos(phi), np.sin(phi)
    out = np.empty_like(c)
    out[..., 0, 0] = l1 * cs * cs + l2 * sn * sn
    out[..., 1, 1] = l1 * sn * sn + l2 * cs * cs
    out[..., 0, 1] = out[..., 1, 0] = (l1 - l2) * cs * sn
    return out


def texture_stats(chain: MipChain, uv, dudv, *, anisotropic: bool = False, max_aniso: int = 8):
    """Mean and std of a tabulated driving function over pixel footprints (section 4.2), with the
    magnification correction of :func:`footprint_stats`.

    Parameters
    ----------
    chain : MipChain
        From :func:`moments_mip` (two channels ``E[f], E[f^2]``).
    uv : array_like, shape (..., 2)
    dudv : array_like, shape (..., 2, 2)
        Footprint Jacobian ``d uv / d pixel``.

    Returns
    -------
    mean, sigma : numpy.ndarray, shape (...)
    """
    if not isinstance(chain, MipChain) or chain.shape[2] != 2:
        raise PrefilterError("chain: expected a two-channel moments MipChain (moments_mip)")
    mean, var = footprint_stats(chain, uv, dudv, anisotropic=anisotropic, max_aniso=max_aniso)
    return mean, np.sqrt(var)


def filter_texture(table, chain: MipChain, uv, dudv, **kw) -> np.ndarray:
    """Filtered colour ``<C, N(f_bar, sigma_f^2)>`` of a colour-mapped texture (eqs. 8, 10),
    shape ``(..., C)``."""
    as_table(table)
    mean, sigma = texture_stats(chain, uv, dudv, **kw)
    return table.lookup(mean, sigma)


def naive_texture(table, chain: MipChain, uv, dudv, **kw) -> np.ndarray:
    """The naive ``C(f_bar)``: the colour map applied to the mip-mapped mean, ``(..., C)``."""
    as_table(table)
    mean, _ = texture_stats(chain, uv, dudv, **kw)
    return table.naive(mean)


class NoiseStd:
    """Std of procedural noise inside a footprint, tabulated per LOD (section 4.2's 1D texture).

    Parameters
    ----------
    level_variance : array_like, shape (n_levels,)
        Variance of the texel values of each box-filtered mip level (level 0 first), e.g.
        :func:`prefilter.texture.procedural.noise_level_variance`.
    sigma : float, optional
        Std of the noise process (default ``sqrt(level_variance[0])``).

    The within-footprint variance at level ``L`` is ``sigma^2 - Var_L``; :meth:`__call__`
    interpolates it linearly in a fractional LOD (clamped to the table) and returns its root.
    """

    def __init__(self, level_variance, sigma: float | None = None):
        v = as_float_array(level_variance, "level_variance", ndim_min=1)
        if v.ndim != 1 or v.size < 1 or np.any(v < 0):
            raise PrefilterError(f"level_variance: expected a 1D array of variances >= 0, got "
                                 f"shape {v.shape}")
        if sigma is None:
            s2 = v[0]
        else:
            s = check_scalar(sigma, "sigma", lo=0.0, hi=1e150)  # s^2 finite
            s2 = s * s
        self.variance = np.maximum(s2 - v, 0.0)  # within-footprint variance per level

    @classmethod
    def from_procedural(cls, size: int = 512, corr_length: float = 4.0, sigma: float = 1.0):
        """The table of :func:`prefilter.texture.procedural.noise` with these parameters."""
        from prefilter.texture.procedural import noise_level_variance

        return cls(noise_level_variance(size, corr_length, sigma), sigma)

    @property
    def std(self) -> np.ndarray:
        """Within-footprint std per level, ``(n_levels,)``."""
        return np.sqrt(self.variance)

    def __call__(self, lod) -> np.ndarray:
        lod = np.clip(as_float_array(lod, "lod"), 0.0, self.variance.size - 1)
        return np.sqrt(np.interp(lod, np.arange(self.variance.size), self.variance))


def filter_noise(table, noise_chain: MipChain, noise_std: NoiseStd, uv, dudv, *,
                 anisotropic: bool = False, max_aniso: int = 8):
    """Colour-mapped procedural noise over pixel footprints (section 4.2): the mean is the noise's
    mip-mapped value over the footprint, the std comes from the per-LOD table.

    Isotropic: both at ``lod = log2(major axis)``. Anisotropic: the mean by the anisotropic lookup,
    the std at the LOD of the square of equal area, ``log2(sqrt(major minor))`` (the variance left
    in a footprint depends on how much of the noise it covers).

    Returns
    -------
    filtered, naive : numpy.ndarray, shape (..., C)
        ``<C, N(mean, sigma(lod)^2)>`` and ``C(mean)``.
    """
    as_table(table)
    if not isinstance(noise_std, NoiseStd):
        raise PrefilterError(f"noise_std: expected a NoiseStd, got {type(noise_std).__name__}")
    if not isinstance(noise_chain, MipChain) or noise_chain.shape[2] != 1:
        raise PrefilterError("noise_chain: expected a one-channel MipChain of the noise")
    h, w = noise_chain.shape[:2]
    if anisotropic:
        mean = noise_chain.lookup_footprint(uv, dudv, anisotropic=True, max_aniso=max_aniso)[..., 0]
        major, minor, _ = footprint_axes(dudv, (h, w))
        lod = 0.5 * np.log2(np.maximum(major * minor, 1.0))
    else:
        lod = lod_from_footprint(dudv, (h, w))
        mean = noise_chain.lookup(uv, lod)[..., 0]
    return table.lookup(mean, noise_std(lod)), table.naive(mean)
