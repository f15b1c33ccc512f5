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

from prefilter._validate import as_float_array
from prefilter.errors import PrefilterError
from prefilter.texture.mip import MipChain, lod_from_footprint, moment_chain, moments_to_stats

__all__ = ["NoiseStd", "filter_noise", "filter_texture", "moments_mip", "naive_texture",
           "texture_stats"]


def moments_mip(data) -> MipChain:
    """Mip chain of ``E[f], E[f^2]`` of a scalar map ``(H, W)`` (section 4.2)."""
    return moment_chain(data)


def texture_stats(chain: MipChain, uv, dudv, *, anisotropic: bool = False, max_aniso: int = 8):
    """Mean and std of a tabulated driving function over pixel footprints (section 4.2).

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
    m = chain.lookup_footprint(uv, dudv, anisotropic=anisotropic, max_aniso=max_aniso)
    mean, var = moments_to_stats(m)
    return mean, np.sqrt(var)


def filter_texture(table, chain: MipChain, uv, dudv, **kw) -> np.ndarray:
    """Filtered colour ``<C, N(f_bar, sigma_f^2)>`` of a colour-mapped texture (eqs. 8, 10),
    shape ``(..., C)``."""
    mean, sigma = texture_stats(chain, uv, dudv, **kw)
    return table.lookup(mean, sigma)


def naive_texture(table, chain: MipChain, uv, dudv, **kw) -> np.ndarray:
    """The naive ``C(f_bar)``: the colour map applied to the mip-mapped mean, ``(..., C)``."""
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
        s2 = v[0] if sigma is None else float(sigma) ** 2
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


def filter_noise(table, noise_chain: MipChain, noise_std: NoiseStd, uv, dudv) -> np.ndarray:
    """Colour-mapped procedural noise over pixel footprints (section 4.2): the mean is the noise's
    mip-mapped value at the footprint's LOD, the std comes from the per-LOD table.

    Returns
    -------
    filtered, naive : numpy.ndarray, shape (..., C)
        ``<C, N(mean, sigma(lod)^2)>`` and ``C(mean)``.
    """
    if not isinstance(noise_chain, MipChain) or noise_chain.shape[2] != 1:
        raise PrefilterError("noise_chain: expected a one-channel MipChain of the noise")
    h, w = noise_chain.shape[:2]
    lod = lod_from_footprint(dudv, (h, w))
    mean = noise_chain.lookup(uv, lod)[..., 0]
    return table.lookup(mean, noise_std(lod)), table.naive(mean)
