"""Anisotropic GGX (Trowbridge-Reitz) microfacet distribution.

Walter et al. 2007 and Heitz 2014 ("Understanding the masking-shadowing function"), eqs. in
``equations.md`` 1; visible-normal sampling from Heitz 2018 (JCGT 7(4)).
"""

from __future__ import annotations

import numpy as np

from prefilter._validate import as_directions, as_roughness, as_uniform
from prefilter.microfacet.base import MicrofacetModel


class GGX(MicrofacetModel):
    """Anisotropic GGX with roughness ``alpha_x`` (tangent) and ``alpha_y`` (bitangent).

    Parameters broadcast against the leading dimensions of the directions passed to the methods.
    ``alpha_y`` defaults to ``alpha_x`` (isotropic).
    """

    def __init__(self, alpha_x, alpha_y=None):
        self.alpha_x = as_roughness(alpha_x, "alpha_x")
        self.alpha_y = self.alpha_x if alpha_y is None else as_roughness(alpha_y, "alpha_y")

    def __repr__(self) -> str:
        return f"GGX(alpha_x={self.alpha_x}, alpha_y={self.alpha_y})"

    def _scalar_params(self) -> bool:
        return self.alpha_x.ndim == 0 and self.alpha_y.ndim == 0

    def _with_trailing_axis(self) -> "GGX":
        return GGX(self.alpha_x[..., None], self.alpha_y[..., None])

    def D(self, m) -> np.ndarray:
        """GGX NDF ``1 / (pi ax ay (mx^2/ax^2 + my^2/ay^2 + mz^2)^2)``, 0 for ``mz <= 0``."""
        m = as_directions(m, "m")
        ax, ay = self.alpha_x, self.alpha_y
        t = (m[..., 0] / ax) ** 2 + (m[..., 1] / ay) ** 2 + m[..., 2] ** 2
        return np.where(m[..., 2] > 0.0, 1.0 / (np.pi * ax * ay * t * t), 0.0)

    def smith_lambda(self, w) -> np.ndarray:
        """Smith ``Lambda(w) = (-1 + sqrt(1 + (ax^2 wx^2 + ay^2 wy^2) / wz^2)) / 2``.

        Written as ``a2 / (1 + sqrt(1 + a2)) / 2`` with ``a2 = (...) / wz^2`` to avoid cancellation
        near normal incidence. Evaluated with ``|wz|`` (the horizon test lives in ``G1``/``G2``).
        """
        w = np.asarray(w, dtype=np.float64)
        wz2 = np.maximum(w[..., 2] ** 2, 1e-300)
        a2 = ((self.alpha_x * w[..., 0]) ** 2 + (self.alpha_y * w[..., 1]) ** 2) / wz2
        return a2 / (1.0 + np.sqrt(1.0 + a2)) / 2.0

    def sample_vndf(self, wo, u) -> np.ndarray:
        """Visible normals ``m (..., 3)`` for views ``wo (..., 3)`` and uniforms ``u (..., 2)``.

        Heitz 2018: stretch, sample the projected hemisphere, unstretch. Density
        :meth:`pdf_vndf`.
        """
        wo = as_directions(wo, "wo")
        u = as_uniform(u, "u", last_dim=2)
        ax, ay = self.alpha_x, self.alpha_y
        vh = np.stack(np.broadcast_arrays(ax * wo[..., 0], ay * wo[..., 1], wo[..., 2]), -1)
        vh = vh / np.linalg.norm(vh, axis=-1, keepdims=True)
        lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
        safe = lensq > 1e-14
        inv = 1.0 / np.sqrt(np.where(safe, lensq, 1.0))
        t1 = np.stack(
            [
                np.where(safe, -vh[..., 1] * inv, 1.0),
                np.where(safe, vh[..., 0] * inv, 0.0),
                np.zeros_like(lensq),
            ],
            -1,
        )
        t2 = np.cross(vh, t1)
        r = np.sqrt(u[..., 0])
        phi = 2.0 * np.pi * u[..., 1]
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vh[..., 2])
        p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
        p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
        nh = p1[..., None] * t1 + p2[..., None] * t2 + p3[..., None] * vh
        m = np.stack(
            np.broadcast_arrays(ax * nh[..., 0], ay * nh[..., 1], np.maximum(1e-12, nh[..., 2])),
            -1,
        )
        return m / np.linalg.norm(m, axis=-1, keepdims=True)
