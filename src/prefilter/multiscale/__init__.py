"""Multi-scale LTC (Tao et al. 2021): antialiased area lighting of normal-mapped surfaces.

``mean_resultant_length`` / ``alpha_meso`` (eqs. 4-5): meso-scale roughness from the length of
an unnormalised mip-averaged normal; ``alpha_total`` (eqs. 6-7): micro- and meso-scale roughness
combined; the render method ``ltc-multiscale`` lives in :mod:`prefilter.multiscale.render`, its
anisotropic extension ``ltc-multiscale-aniso`` (LEAN slope moments, anisotropic LTC table) in
:mod:`prefilter.multiscale.aniso`.
"""

from prefilter.multiscale.convolution import (
    FIT_COEFFS,
    PAPER_EQ7,
    alpha_total,
    convolution_grid,
    convolve_samples,
    fit_alpha_ml,
    fit_polynomial,
    sample_ltc_iso,
)
from prefilter.multiscale.meso import (
    PAPER_EQ5,
    alpha_meso,
    alpha_meso_exact,
    mean_resultant_length,
)

__all__ = [
    "FIT_COEFFS",
    "PAPER_EQ5",
    "PAPER_EQ7",
    "alpha_meso",
    "alpha_meso_exact",
    "alpha_total",
    "convolution_grid",
    "convolve_samples",
    "fit_alpha_ml",
    "fit_polynomial",
    "mean_resultant_length",
    "sample_ltc_iso",
]
