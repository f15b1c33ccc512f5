"""The ``ltc-multiscale`` method's compiled shader: the ``ltc`` kernel per sample with the
roughness of Tao et al. 2021, eqs. 4-7, from the length ``r`` of the footprint's averaged normal.

Per sample: the renderer's surface (:func:`prefilter.render.kernels.surface_sample`: ray, hit,
the normal map's footprint read, shading frame, material), ``alpha_total`` of ``r``
(:func:`multiscale_alpha`, the same formulas as :func:`prefilter.multiscale.alpha_total`) and the
``ltc`` shader of one point (:func:`prefilter.ltc.kernels.ltc_point`).
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, njit_serial, prange
from prefilter.ltc.kernels import BLOCK, ltc_point, ltc_scratch
from prefilter.multiscale.convolution import eq7_fit_form, eq7_paper_form
from prefilter.multiscale.meso import _paper_eq5
from prefilter.render.kernels import gscratch, surface_sample

__all__ = ["MESO_EQ5", "MESO_TABLE", "RGH_WIDTH", "ROUGH_EQ7", "ROUGH_FIT", "ROUGH_MRL",
           "multiscale_alpha", "multiscale_samples_kernel"]

# Per-material roughness rows (``RGH_*`` are column offsets): how ``alpha_total`` follows from the
# footprint (``RGH_MODE``), the meso-scale inverse of eq. 4 (``RGH_MESO``), alpha_micro, the
# coefficients of alpha_total and r(alpha_micro) for mean-resultant-length matching.
RGH_MODE, RGH_MESO, RGH_ALPHA, RGH_COEF, RGH_MRL = 0, 1, 2, 3, 7
RGH_WIDTH = 8
#: ``RGH_MODE`` values: our form of eq. 7 (``multiscale.convolution``, "fit"); eq. 7's polynomial
#: ("paper"); mean-resultant-length matching ("mrl").
ROUGH_FIT, ROUGH_EQ7, ROUGH_MRL = 1, 2, 3
#: ``RGH_MESO`` values: the tabulated exact inverse of eq. 4, or eq. 5 (clamped as the paper).
MESO_TABLE, MESO_EQ5 = 0, 1

_eq7_fit = njit_inline(eq7_fit_form)
_eq7_paper = njit_inline(eq7_paper_form)
_eq5 = njit_inline(_paper_eq5)


@njit_serial
def _interp_uniform(x, tab):
    """Linear interpolation of ``tab`` sampled at ``linspace(0, 1, len(tab))``, ``x`` clamped."""
    n = tab.shape[0]
    f = min(max(x, 0.0), 1.0) * (n - 1)
    i = min(np.int64(f), n - 2)
    t = f - i
    return tab[i] * (1.0 - t) + tab[i + 1] * t


@njit_serial
def multiscale_alpha(row, r, meso_tab):
    """Tao et al. 2021, eqs. 4-7: ``alpha_total`` from the length ``r`` of the footprint's
    averaged normal. ``meso_tab``: ``alpha_meso`` at ``x = sqrt(3 (1 - r))`` uniform in [0, 1]
    (``x`` makes the inverse of eq. 4 nearly linear)."""
    a = row[RGH_ALPHA]
    rc = min(max(r, 2.0 / 3.0), 1.0)
    if row[RGH_MESO] == MESO_TABLE:
        b = _interp_uniform(math.sqrt(min(max(3.0 * (1.0 - r), 0.0), 1.0)), meso_tab)
    else:
        b = min(max(_eq5(rc), 0.0), 1.0)
    c = RGH_COEF
    mode = row[RGH_MODE]
    if mode == ROUGH_FIT:
        out = _eq7_fit(a, b, row[c], row[c + 1], row[c + 2], row[c + 3])
    elif mode == ROUGH_EQ7:
        out = _eq7_paper(a, b, row[c], row[c + 1], row[c + 2], row[c + 3])
    else:
        # mean resultant lengths multiply under convolution; r(alpha_meso) is r itself (clamped)
        rr = row[RGH_MRL] * rc
        out = _interp_uniform(math.sqrt(min(max(3.0 * (1.0 - rr), 0.0), 1.0)), meso_tab)
    return min(max(out, 0.0), 1.0)


@njit_parallel
def multiscale_samples_kernel(cam, xy, types, params, mat_f, mat_i, data, info, tex, read,
                              rough, meso_tab, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag,
                              tab_fres, view_z_min, rad, status):
    """:func:`prefilter.ltc.kernels.ltc_samples_kernel` with the roughness of
    :func:`multiscale_alpha` (``rough (K, RGH_WIDTH)`` per material, ``meso_tab``). Writes
    ``rad (N, 3)`` (0 on misses); ``status[k] = 1`` flags a singular LTC matrix."""
    n_pts = xy.shape[0]
    n_blocks = (n_pts + BLOCK - 1) // BLOCK
    for blk in prange(n_blocks):
        geo, mat, P, C, ident, tm, mm, res = ltc_scratch()
        gs = gscratch()
        tx = np.empty((2, 4))
        for k in range(blk * BLOCK, min(n_pts, (blk + 1) * BLOCK)):
            rad[k, 0] = 0.0
            rad[k, 1] = 0.0
            rad[k, 2] = 0.0
            hit, o, r = surface_sample(cam, xy[k, 0], xy[k, 1], types, params, mat_f, mat_i,
                                       data, info, tex, read, gs, tx, geo, mat)
            if not hit:
                continue
            mat[0] = multiscale_alpha(rough[o], r, meso_tab)
            for c in range(3):
                res[c] = 0.0
            if ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                         view_z_min, P, C, ident, tm, mm, res):
                rad[k, 0] = res[0]
                rad[k, 1] = res[1]
                rad[k, 2] = res[2]
            else:
                status[k] = 1
