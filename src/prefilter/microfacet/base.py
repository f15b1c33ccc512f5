"""The interface every microfacet model shares (pbrt's ``f`` / ``Sample_f`` / ``PDF`` triple).

Subclasses provide the NDF ``D``, Smith's ``smith_lambda`` and visible-normal sampling
``sample_vndf``; everything else (masking, the cosine-weighted BRDF, exact lobe sampling, albedo)
follows from those here. Local frame: z = macro normal, x = tangent. Fresnel is 1 throughout.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import (
    as_directions,
    as_float_array,
    as_positive_int,
    as_rng,
    as_upper_directions,
)
from prefilter.lobe import Lobe, sample_weight


def reflect(wo: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Mirror ``wo (..., 3)`` about microfacet normals ``m (..., 3)``: ``2 (wo.m) m - wo``."""
    wo = as_float_array(wo, "wo", ndim_min=1, last_dim=3)
    m = as_float_array(m, "m", ndim_min=1, last_dim=3)
    return 2.0 * np.sum(wo * m, axis=-1, keepdims=True) * m - wo


def half_vector(wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """``normalize(wo + wi)``; zero-length sums (opposite directions) give ``(0, 0, 1)``."""
    h = as_float_array(wo, "wo", ndim_min=1, last_dim=3) + as_float_array(wi, "wi", ndim_min=1,
                                                                           last_dim=3)
    n = np.linalg.norm(h, axis=-1, keepdims=True)
    safe = n > 1e-12
    return np.where(safe, h / np.where(safe, n, 1.0), np.array([0.0, 0.0, 1.0]))


#: Largest expected number of VNDF proposals :meth:`MicrofacetModel.sample_lobe` accepts to draw.
_MAX_PROPOSALS = 1e9


class MicrofacetModel(Lobe):
    """Base class: Smith masking, the cosine-weighted BRDF, exact lobe sampling, albedo.

    As a :class:`~prefilter.lobe.Lobe`, it samples by reflecting visible normals
    (:meth:`sample`, density :meth:`pdf_reflect`).
    """

    #: Number of quadrature nodes per axis used by :meth:`albedo`.
    albedo_nodes: int = 64

    # -- provided by subclasses ------------------------------------------------------------------
    def D(self, m) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def smith_lambda(self, w) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def sample_vndf(self, wo, u) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _scalar_params(self) -> bool:  # pragma: no cover - abstract
        raise NotImplementedError

    def _with_trailing_axis(self) -> "MicrofacetModel":  # pragma: no cover - abstract
        """The same model with parameters reshaped to broadcast against one more trailing axis."""
        raise NotImplementedError

    # -- overridden by non-centred models --------------------------------------------------------
    def mean_projected_area(self, w) -> np.ndarray:
        """Projected area of the mean surface per unit geometric area, ``(n_bar.w) / (n_bar.z)``.

        ``w_z`` for centred NDFs (mean normal = z); ``(...,)`` for ``w (..., 3)``. LEADR
        supplemental 1.5, eq. 9. May be negative (``w`` below the mean surface).
        """
        return as_directions(w, "w")[..., 2]

    def projected_area(self, w) -> np.ndarray:
        """Back-face-culled projected area ``integral max(0, w.m) D(m) dm`` for ``w (..., 3)``.

        Smith's identity (LEADR supplemental eq. 9): ``(1 + Lambda(w))`` times the mean surface's
        projected area. It normalises the visible-normal density :meth:`pdf_vndf`.
        """
        w = as_directions(w, "w")
        return self.mean_projected_area(w) * (1.0 + self.smith_lambda(w))

    # -- shared ----------------------------------------------------------------------------------
    def G1(self, w) -> np.ndarray:
        """Smith masking ``1 / (1 + Lambda(w))`` for ``w (..., 3)``; 0 below the horizon."""
        w = as_directions(w, "w")
        lam = self.smith_lambda(w)
        return np.where(w[..., 2] > 0.0, 1.0 / (1.0 + lam), 0.0)

    def G2(self, wo, wi) -> np.ndarray:
        """Height-correlated masking-shadowing ``1 / (1 + Lambda(wo) + Lambda(wi))``."""
        wo = as_directions(wo, "wo")
        wi = as_directions(wi, "wi")
        g = 1.0 / (1.0 + self.smith_lambda(wo) + self.smith_lambda(wi))
        return np.where((wo[..., 2] > 0.0) & (wi[..., 2] > 0.0), g, 0.0)

    def eval(self, wo, wi) -> np.ndarray:
        """Cosine-weighted BRDF ``f(wo, wi) wi_z = D(h) G2(wo, wi) / (4 A(wo))`` (Fresnel 1).

        ``A(wo)`` is :meth:`mean_projected_area`, ``wo_z`` for centred models (Walter et al. 2007
        eq. 20; for non-centred slopes the radiance is per projected area of the mean surface,
        LEADR supplemental 3.3). Zero when either direction is at or below the horizon or below
        the mean surface. ``(...,)`` for ``wo, wi (..., 3)``.
        """
        wo = as_directions(wo, "wo")
        wi = as_directions(wi, "wi")
        h = half_vector(wo, wi)
        area = self.mean_projected_area(wo)
        lam_o = self.smith_lambda(wo)
        lam_i = self.smith_lambda(wi)
        up = (wo[..., 2] > 0.0) & (wi[..., 2] > 0.0) & (area > 0.0) & np.isfinite(lam_o + lam_i)
        safe_area = np.where(up, area, 1.0)
        g2 = np.where(up, 1.0 / (1.0 + np.where(up, lam_o + lam_i, 0.0)), 0.0)
        val = self.D(h) * g2 / (4.0 * safe_area)
        return np.where(up, val, 0.0)

    def pdf_vndf(self, wo, m) -> np.ndarray:
        """Density of :meth:`sample_vndf` (solid angle), ``(...,)``.

        ``max(0, wo.m) D(m) / integral max(0, wo.m) D(m) dm`` (Heitz 2014 eq. 16); equal to
        ``G1(wo) max(0, wo.m) D(m) / wo_z`` for centred NDFs. Zero for ``wo_z <= 0``.
        """
        wo = as_directions(wo, "wo")
        m = as_directions(m, "m")
        dot = np.maximum(0.0, np.sum(wo * m, axis=-1))
        area = self.projected_area(wo)
        ok = (wo[..., 2] > 0) & (area > 0.0)
        return np.where(ok, dot * self.D(m) / np.where(ok, area, 1.0), 0.0)

    def pdf_reflect(self, wo, wi) -> np.ndarray:
        """Density of ``wi = reflect(wo, m)`` with ``m`` from :meth:`sample_vndf`."""
        wo = as_directions(wo, "wo")
        wi = as_directions(wi, "wi")
        h = half_vector(wo, wi)
        dot = np.sum(wo * h, axis=-1)
        safe = dot > 1e-12
        return np.where(safe, self.pdf_vndf(wo, h) / (4.0 * np.where(safe, dot, 1.0)), 0.0)

    def pdf(self, wo, wi) -> np.ndarray:
        """Lobe interface: the density of :meth:`sample`, :meth:`pdf_reflect`."""
        return self.pdf_reflect(wo, wi)

    def sample_reflect(self, wo, u) -> np.ndarray:
        """``wi = reflect(wo, m) (..., 3)`` with ``m`` from :meth:`sample_vndf` (Heitz 2018),
        density :meth:`pdf_reflect`. ``wo (..., 3)``, ``u (..., 2)``."""
        wi = reflect(wo, self.sample_vndf(wo, u))
        return wi / np.linalg.norm(wi, axis=-1, keepdims=True)

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:
        """Lobe interface: :meth:`sample_reflect` and the weight ``eval / pdf`` (``G2 / G1``
        for centred models; 0 below the horizon). ``wo (..., 3)``, ``u (..., 2)``."""
        wi = self.sample_reflect(wo, u)
        return wi, sample_weight(self.eval(wo, wi), self.pdf_reflect(wo, wi))

    def sample_lobe(self, wo, n: int, rng) -> np.ndarray:
        """``n`` exact samples ``(n, 3)`` of the normalised cosine-weighted lobe ``eval(wo, .)``.

        Algorithm 1 of the anisotropic-LTC paper: reflect a visible normal, accept with probability
        ``G2(wo, wi) / G1(wo)`` (<= 1). Needs scalar roughness parameters and one view ``wo (3,)``.
        """
        wo = as_upper_directions(wo, "wo")
        if wo.shape != (3,):
            raise_shape("wo", wo.shape, "(3,)")
        if not self._scalar_params():
            from prefilter.errors import PrefilterError

            raise PrefilterError("sample_lobe: roughness parameters must be scalars")
        n = as_positive_int(n, "n")
        rng = as_rng(rng)
        g1o = float(self.G1(wo))
        if not g1o > 0.0:
            from prefilter.errors import PrefilterError

            raise PrefilterError(
                f"wo: the lobe is empty (G1 = 0, wo = {wo} faces away from the mean surface)"
            )
        # Every proposal is accepted with probability albedo(wo) (E_vndf[G2 / G1]): a lobe whose
        # reflections all leave below the horizon (albedo 0 with G1 > 0, e.g. a near-mirror mean
        # surface tilted away from a grazing view) would loop forever.
        alb = float(self.albedo(wo))
        if not n / max(alb, 1e-300) <= _MAX_PROPOSALS:
            from prefilter.errors import PrefilterError

            raise PrefilterError(
                f"wo: the lobe is empty or nearly so (albedo {alb:.3g} at wo = {wo}: reflections "
                f"leave below the horizon); {n} samples would need ~{n / max(alb, 1e-300):.3g} "
                f"proposals (limit {_MAX_PROPOSALS:.0e})"
            )
        out = []
        have = 0
        lam_o = float(self.smith_lambda(wo))
        rate = 0.5
        while have < n:
            batch = int(min(1_000_000, max(1024, 1.2 * (n - have) / max(rate, 1e-3))))
            m = self.sample_vndf(wo, rng.random((batch, 2)))
            wi = reflect(wo, m)
            ok = wi[:, 2] > 0.0
            g2 = np.zeros(batch)
            g2[ok] = 1.0 / (1.0 + lam_o + self.smith_lambda(wi[ok]))
            acc = ok & (rng.random(batch) * g1o < g2)
            rate = max(acc.mean(), 1e-3)
            out.append(wi[acc])
            have += int(acc.sum())
        return np.concatenate(out)[:n]

    def albedo(self, wo) -> np.ndarray:
        """Directional albedo ``integral eval(wo, wi) dwi`` (Fresnel 1) for ``wo (..., 3)``.

        Deterministic: Gauss-Legendre quadrature in the unit square of visible-normal sampling,
        where the integrand is ``G2 / G1`` (smooth except at the horizon).
        """
        wo = as_directions(wo, "wo")
        k = self.albedo_nodes
        x, w = np.polynomial.legendre.leggauss(k)
        x = (x + 1) / 2
        u = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
        wgt = (w[:, None] * w[None, :]).reshape(-1) / 4
        wo_b = wo[..., None, :]
        model = self._with_trailing_axis()
        m = model.sample_vndf(wo_b, u)
        wi = reflect(wo_b, m)
        lam_o = self.smith_lambda(wo)
        lam_i = model.smith_lambda(wi)
        seen = (wo[..., 2] > 0.0) & np.isfinite(lam_o)
        # G2 / G1 = 1 / (1 + Lambda_i / (1 + Lambda_o)); Lambda_i = inf gives 0, not NaN.
        ratio = 1.0 / (1.0 + lam_i / (1.0 + np.where(seen, lam_o, 0.0))[..., None])
        ratio = np.where(wi[..., 2] > 0.0, ratio, 0.0)
        return np.where(seen, np.sum(ratio * wgt, axis=-1), 0.0)


def raise_shape(name, shape, expected):
    from prefilter.errors import PrefilterError

    raise PrefilterError(f"{name}: expected shape {expected}, got {shape}")
