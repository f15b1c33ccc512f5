"""The multi-scale lobe: the LTC lobe at a footprint's total roughness (Tao et al. 2021, eq. 7).

A footprint whose averaged (unnormalised) normal has length ``r`` spreads its normals as an
isotropic GGX of roughness ``alpha_meso(r)`` (eqs. 4-5); convolved with the micro-scale GGX it is
shaded as one GGX of roughness ``alpha_total(alpha_micro, alpha_meso)`` (eqs. 6-7) in the frame
of the averaged normal (z = its direction), through the LTC table.
"""

from __future__ import annotations

import numpy as np

from prefilter.ltc.lobe import LTCLobe
from prefilter.multiscale.convolution import alpha_total
from prefilter.multiscale.meso import alpha_meso


class MultiscaleLobe(LTCLobe):
    """:class:`~prefilter.ltc.lobe.LTCLobe` of the isotropic GGX table at ``alpha_total``.

    Parameters
    ----------
    alpha_micro : (...) micro-scale GGX roughness (clamped to 1, as the render method does).
    r : (...) mean resultant length of the footprint's normals, in ``[0, 1]``.
    meso : {"exact", "paper"} variant of :func:`~prefilter.multiscale.alpha_meso`.
    total : {"fit", "paper", "mrl"} variant of :func:`~prefilter.multiscale.alpha_total`.
    table, f0 : as :class:`~prefilter.ltc.lobe.LTCLobe`.
    """

    def __init__(self, alpha_micro, r, *, meso: str = "exact", total: str = "fit", table=None,
                 f0=None):
        self.alpha_micro = np.minimum(np.asarray(alpha_micro, dtype=np.float64), 1.0)
        self.alpha_meso = alpha_meso(r, meso)
        super().__init__(alpha_total(self.alpha_micro, self.alpha_meso, total), table=table,
                         f0=f0)
