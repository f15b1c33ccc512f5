"""Microfacet models: anisotropic GGX and non-centred anisotropic Beckmann.

Both share :class:`~prefilter.microfacet.base.MicrofacetModel`: ``D``, ``smith_lambda``, ``G1``,
``G2``, ``eval`` (cosine-weighted BRDF, Fresnel 1), ``sample_vndf``, ``pdf_vndf``,
``sample_lobe`` (exact lobe samples) and ``albedo``.
"""

from prefilter.microfacet.base import MicrofacetModel, half_vector, reflect
from prefilter.microfacet.ggx import GGX

__all__ = ["GGX", "MicrofacetModel", "half_vector", "reflect"]
