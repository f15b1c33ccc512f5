"""The glint lobe: one pixel footprint's glint BRDF as a :class:`~prefilter.lobe.Lobe`.

Glints tensor-prefiltering paper, eq. 1 and sec. 5.1-5.2: ``eval`` is
:func:`~prefilter.glints.brdf.glint_brdf_cos` (footprint P-NDF, V-cavity masking, Schlick
Fresnel), draws reflect half vectors of the footprint's NDF (:func:`~prefilter.glints.sample_wi`,
density :func:`~prefilter.glints.sample.pdf_wi`). The footprint ``(center, sigma_p)`` is fixed at
construction; the lobe is batched over directions in the geometric tangent frame.

NDF samples the sampler cannot turn into a direction (an empty image, ``|s| >= 1``, a half vector
facing away from ``wo``) come back as ``-wo`` with weight 0, so ``pdf`` integrates to the
fraction of draws that succeed.
"""

from __future__ import annotations

import numpy as np

from prefilter.glints.brdf import as_surface, glint_brdf_cos
from prefilter.glints.sample import n_uniforms, pdf_wi, sample_wi
from prefilter.lobe import Lobe, sample_weight
from prefilter.validation import as_directions, as_float_array

#: Uniforms of the direct P-NDF sampler (element choice, Box-Muller pair).
DIRECT_UNIFORMS = 3


class GlintLobe(Lobe):
    """Glint BRDF of the footprint ``center (2,)`` (texels), ``sigma_p`` (texels) of ``surf``.

    ``surf``: a :class:`~prefilter.glints.brdf.GlintSurface` (:func:`~prefilter.glints.surface`;
    one with only a normal map uses the direct P-NDF everywhere) or a
    :class:`~prefilter.glints.GlintsMap`. ``f0``: Schlick reflectance, a scalar (results
    ``(...,)``) or ``(C,)`` (results ``(..., C)``).
    """

    def __init__(self, surf, center, sigma_p, f0=1.0):
        self.surf = as_surface(surf)
        self.center = as_float_array(center, "center", ndim_min=1, last_dim=2)
        self.sigma_p = float(as_float_array(sigma_p, "sigma_p"))
        self.f0 = np.asarray(f0, dtype=np.float64)
        direct = self.surf.normal_map is not None and self.sigma_p < self.surf.sigma0
        self.n_uniforms = DIRECT_UNIFORMS if direct else max(DIRECT_UNIFORMS,
                                                             n_uniforms(self.surf.gm))

    def __repr__(self) -> str:
        return f"GlintLobe(center={self.center.tolist()}, sigma_p={self.sigma_p})"

    def _colour(self, val):
        return val[..., 0] if self.f0.ndim == 0 else val

    def eval(self, wo, wi) -> np.ndarray:
        """:func:`~prefilter.glints.brdf.glint_brdf_cos` of the footprint."""
        return self._colour(glint_brdf_cos(self.surf, self.center, self.sigma_p, wo, wi,
                                           self.f0))

    def pdf(self, wo, wi) -> np.ndarray:
        """:func:`~prefilter.glints.sample.pdf_wi` of the footprint, ``(...,)``."""
        return pdf_wi(self.surf, self.center, self.sigma_p, wo, wi)

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~prefilter.glints.sample_wi` from ``u (..., n_uniforms)`` and the weights."""
        wo = as_directions(wo, "wo")
        u = as_float_array(u, "u", ndim_min=1, last_dim=self.n_uniforms)
        shape = np.broadcast_shapes(wo.shape[:-1], u.shape[:-1])
        wo = np.broadcast_to(wo, shape + (3,))
        # sample_wi draws one direction per footprint: repeat the footprint over the batch.
        wi, pdf = sample_wi(self.surf, np.broadcast_to(self.center, shape + (2,)), self.sigma_p,
                            wo, u=np.broadcast_to(u, shape + u.shape[-1:]).reshape(
                                -1, u.shape[-1]))
        ok = pdf > 0.0
        wi = wi / np.maximum(np.linalg.norm(wi, axis=-1, keepdims=True), 1e-300)
        wi = np.where(ok[..., None], wi, -wo)  # failed draws: below the horizon, weight 0
        # The weight divides by pdf_wi, not by the sampler's own density: the direct P-NDF's
        # evaluator drops element Gaussians beyond 6 stds, the sampler's density keeps them, so
        # the two differ by up to ~1e-3 relative in the NDF's far tails.
        return wi, sample_weight(self.eval(wo, wi), np.where(ok, self.pdf(wo, wi), 0.0))
