"""The LEADR lobe: a footprint's non-centred anisotropic Beckmann as a :class:`Lobe`.

Dupuy et al. 2013 and its supplemental (3.1-3.3): micro-slopes ``N(mu, Sigma)`` from the
footprint's LEADR moments; ``eval`` is :func:`~prefilter.leadr.shading.point_light` (the
cosine-weighted BRDF with Smith masking-shadowing of the non-centred slopes) restricted to the
upper hemisphere of the geometric surface (local frame, z = macro normal); draws reflect the
exact visible normals of :class:`~prefilter.microfacet.Beckmann` (its :meth:`pdf_reflect`).
"""

from __future__ import annotations

import numpy as np

from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import point_light
from prefilter.lobe import Lobe, sample_weight
from prefilter.microfacet import Beckmann
from prefilter.validation import as_directions


class LeadrLobe(Lobe):
    """Specular lobe of slopes ``N(mean_slope (..., 2), slope_cov (..., 2, 2))``.

    ``f0``: Schlick reflectance (``None``: Fresnel 1); ``shadowing`` and ``lambda_fit``: as
    :func:`~prefilter.leadr.shading.point_light`.
    """

    def __init__(self, mean_slope, slope_cov, *, f0=None, shadowing: bool = True,
                 lambda_fit: str = "exact"):
        self.model = Beckmann(mean_slope, slope_cov)
        self.f0 = f0
        self.shadowing = bool(shadowing)
        self.lambda_fit = lambda_fit

    @classmethod
    def from_moments(cls, moments, alpha_x, alpha_y=None, **kwargs) -> "LeadrLobe":
        """The lobe of a footprint's LEADR moments ``(..., 5)`` over a micro-surface of Beckmann
        roughness ``alpha_x, alpha_y`` (slope variances ``alpha^2 / 2`` added), as the render
        method shades it (:func:`prefilter.leadr.render.leadr_stats`)."""
        ay = alpha_x if alpha_y is None else alpha_y
        mean, cov = shading_stats(moments, 0.0)
        cov = cov.copy()
        cov[..., 0, 0] += 0.5 * np.asarray(alpha_x, dtype=np.float64) ** 2
        cov[..., 1, 1] += 0.5 * np.asarray(ay, dtype=np.float64) ** 2
        return cls(mean, cov, **kwargs)

    def __repr__(self) -> str:
        return (f"LeadrLobe(mean_slope={self.model.mean_slope.tolist()}, "
                f"slope_cov={self.model.slope_cov.tolist()})")

    def eval(self, wo, wi) -> np.ndarray:
        """:func:`~prefilter.leadr.shading.point_light` where ``wo_z, wi_z > 0``, else 0."""
        wo = as_directions(wo, "wo")
        wi = as_directions(wi, "wi")
        val = point_light(wo, wi, self.model.mean_slope, self.model.slope_cov, f0=self.f0,
                          shadowing=self.shadowing, lambda_fit=self.lambda_fit)
        return np.where((wo[..., 2] > 0.0) & (wi[..., 2] > 0.0), val, 0.0)

    def pdf(self, wo, wi) -> np.ndarray:
        """Density of reflected visible normals, :meth:`Beckmann.pdf_reflect`."""
        return self.model.pdf_reflect(wo, wi)

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:
        """Reflected visible normals (``u (..., 2)``) and their weights ``eval / pdf``."""
        wi = self.model.sample_reflect(wo, u)
        return wi, sample_weight(self.eval(wo, wi), self.pdf(wo, wi))

    def albedo(self, wo) -> np.ndarray:
        """:meth:`Beckmann.albedo` for the lobe it equals (Fresnel 1, exact Smith shadowing)."""
        if self.f0 is not None or not self.shadowing or self.lambda_fit != "exact":
            return super().albedo(wo)
        return self.model.albedo(wo)
