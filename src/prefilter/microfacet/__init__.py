"""Microfacet models: anisotropic GGX and non-centred anisotropic Beckmann.

Both share :class:`~prefilter.microfacet.base.MicrofacetModel`: ``D``, ``smith_lambda``, ``G1``,
``G2``, ``eval`` (cosine-weighted BRDF, Fresnel 1), ``sample_vndf``, ``pdf_vndf``, ``pdf_reflect``,
``sample_lobe`` (exact lobe samples), ``albedo``, ``projected_area`` and ``mean_projected_area``.
"""

from prefilter.microfacet.base import MicrofacetModel, half_vector, reflect
from prefilter.microfacet.beckmann import Beckmann, beckmann_lambda, smith_lambda_walter
from prefilter.microfacet.ggx import GGX

__all__ = [
    "Beckmann",
    "GGX",
    "MicrofacetModel",
    "beckmann_lambda",
    "half_vector",
    "reflect",
    "smith_lambda_walter",
]
