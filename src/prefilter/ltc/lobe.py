"""The LTC lobe: the GGX tables' fit of ``BRDF * cos`` as a :class:`~prefilter.lobe.Lobe`.

Heitz, Dupuy, Hill, Neubelt 2016, eq. 1 and section 4: ``f(wo, wi) cos = n(wo) D_M(wo)(wi)``
with the table's matrix ``M``, magnitude ``n`` and (for Schlick Fresnel) the scale of
:func:`~prefilter.ltc.table.schlick_scale`. ``D_M`` is sampled exactly (:meth:`LTC.sample`), so
``pdf = D_M`` and every draw weighs ``n``: the albedo. ``eval`` is the distribution itself,
including the small mass a fit may put below the horizon, which the polygon integral counts too
(it clips in the cosine's frame, :mod:`prefilter.sphere.polygon`).
"""

from __future__ import annotations

import numpy as np

from prefilter.lobe import Lobe
from prefilter.ltc.ltc import LTC
from prefilter.ltc.table import GGXTable, schlick_scale
from prefilter.errors import PrefilterError
from prefilter.validation import as_directions


class LTCLobe(Lobe):
    """LTC fit of GGX(``alpha_x``, ``alpha_y``) read from ``table`` (Fresnel 1, or ``f0``).

    ``table``: a :class:`~prefilter.ltc.table.GGXTable` (isotropic: ``alpha_y`` must be ``None``;
    default: the shipped table) or an :class:`~prefilter.ltc.aniso.AnisoGGXTable` (``alpha_y``
    defaults to ``alpha_x``). Roughness ``(...)`` broadcasts against the directions' batch;
    views at or below the horizon give an empty lobe (eval, pdf and weights 0).
    """

    def __init__(self, alpha_x, alpha_y=None, *, table=None, f0=None):
        self.table = GGXTable.load() if table is None else table
        if alpha_y is not None and isinstance(self.table, GGXTable):
            raise PrefilterError("table: expected an AnisoGGXTable for an anisotropic lobe "
                                 "(alpha_y given), got the isotropic GGXTable")
        self.alpha_x = np.asarray(alpha_x, dtype=np.float64)
        self.alpha_y = None if alpha_y is None else np.asarray(alpha_y, dtype=np.float64)
        self.f0 = f0

    def __repr__(self) -> str:
        return f"{type(self).__name__}(alpha_x={self.alpha_x}, alpha_y={self.alpha_y})"

    def fit(self, wo):
        """``(LTC, scale, seen)`` for views ``wo (..., 3)``: the table's distribution, the
        magnitude (times Schlick's scale for ``f0``) and the mask of views above the horizon."""
        wo = as_directions(wo, "wo")
        seen = wo[..., 2] > 0.0
        # Views at or below the horizon look up the normal view and are masked out afterwards.
        wo = np.where(seen[..., None], wo, np.array([0.0, 0.0, 1.0]))
        if isinstance(self.table, GGXTable):
            M, mag, fres = self.table.lookup(wo, self.alpha_x)
        else:
            ay = self.alpha_x if self.alpha_y is None else self.alpha_y
            M, mag, fres = self.table.lookup(wo, self.alpha_x, ay)
        scale = mag if self.f0 is None else schlick_scale(mag, fres, self.f0)
        return LTC(M), np.where(seen, scale, 0.0), seen

    def eval(self, wo, wi) -> np.ndarray:
        """``n(wo) D_M(wi)`` ``(...,)`` for ``wo, wi (..., 3)``."""
        ltc, scale, _ = self.fit(wo)
        return scale * ltc.eval(wi)

    def pdf(self, wo, wi) -> np.ndarray:
        """``D_M(wi)`` ``(...,)`` (0 for views at or below the horizon)."""
        ltc, _, seen = self.fit(wo)
        return np.where(seen, ltc.eval(wi), 0.0)

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:
        """Exact draws of ``D_M`` (``u (..., 2)``) and their weight ``n(wo)``."""
        ltc, scale, seen = self.fit(wo)
        wi = ltc.sample(u)
        return wi, np.where(seen & (ltc.eval(wi) > 0.0), scale, 0.0)

    def albedo(self, wo) -> np.ndarray:
        """``n(wo)`` (times Schlick's scale for ``f0``): ``D_M`` integrates to 1."""
        return self.fit(wo)[1]
