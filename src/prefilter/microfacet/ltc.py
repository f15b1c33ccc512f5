"""GGX as a linearly transformed cosine, for the compiled kernels: the lookup of a fitted table
and the density of the looked-up distribution.

Heitz, Dupuy, Hill, Neubelt 2016, section 4 (the table of ``M`` over ``(theta_o, alpha)``, rotated
to the view's azimuth) and eq. 1 (``D_M(w) = Do(M^-1 w / |M^-1 w|) |M^-1| / |M^-1 w|^3``). The
table's arrays are those of :class:`prefilter.ltc.table.GGXTable` (``axis_t``, ``axis_r``, ``M``,
``magnitude``, ``fresnel``); the ``ltc`` shader and the reference's control variate read them
through these helpers. The matrix is handed around as ``tm (10,)``: ``sign(det M) adj(M)``
scaled to a largest entry of 1 (row-major, ``tm[:9]``) and ``tm[9] = sign(det M)``, the form
:func:`prefilter.sphere.polygon.polygon_integral_jit` integrates.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_serial
from prefilter.sphere.polygon import signed_adjugate

__all__ = ["interp_index", "ltc_density", "ltc_lookup"]


@njit_serial
def interp_index(x, xp):
    """``np.interp(x, xp, arange(len(xp)))`` for increasing ``xp``."""
    n = xp.shape[0]
    if x <= xp[0]:
        return 0.0
    if x >= xp[n - 1]:
        return n - 1.0
    lo = 0
    hi = n - 1
    while hi - lo > 1:  # xp[lo] <= x < xp[hi]
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo + (x - xp[lo]) / (xp[lo + 1] - xp[lo])


@njit_serial
def ltc_lookup(wx, wy, wz, alpha, axis_t, axis_r, tab_m, tab_mag, tab_fres, mm, tm):
    """The table's LTC for the unit view ``(wx, wy, wz)`` (shading frame, ``wz > 0``) and GGX
    ``alpha``: writes ``tm (10,)`` (module docstring; scratch ``mm (9,)``) and returns
    ``(ok, magnitude, fresnel)``, the bilinear interpolation in ``(sqrt(1 - cos theta),
    sqrt(alpha))`` (``alpha`` clamped to the table). ``ok`` is False for a singular interpolated
    matrix (``tm`` then holds no LTC)."""
    nt = axis_t.shape[0]
    nr = axis_r.shape[0]
    a_min = axis_r[0] * axis_r[0]
    # bilinear table lookup in (sqrt(1 - cos theta), sqrt(alpha))
    ft = interp_index(math.sqrt(max(0.0, 1.0 - wz)), axis_t)
    fr = interp_index(math.sqrt(min(max(alpha, a_min), 1.0)), axis_r)
    i = min(np.int64(math.floor(ft)), nt - 2)
    j = min(np.int64(math.floor(fr)), nr - 2)
    a = ft - i
    b = fr - j
    w00 = (1 - a) * (1 - b)
    w10 = a * (1 - b)
    w01 = (1 - a) * b
    w11 = a * b
    for e in range(9):
        r_ = e // 3
        c_ = e % 3
        mm[e] = (w00 * tab_m[i, j, r_, c_] + w10 * tab_m[i + 1, j, r_, c_]
                 + w01 * tab_m[i, j + 1, r_, c_] + w11 * tab_m[i + 1, j + 1, r_, c_])
    mag = (w00 * tab_mag[i, j] + w10 * tab_mag[i + 1, j] + w01 * tab_mag[i, j + 1]
           + w11 * tab_mag[i + 1, j + 1])
    fres = (w00 * tab_fres[i, j] + w10 * tab_fres[i + 1, j] + w01 * tab_fres[i, j + 1]
            + w11 * tab_fres[i + 1, j + 1])
    # Rz(phi) M Rz(phi)^T, phi the view's azimuth
    rho = math.sqrt(wx * wx + wy * wy)
    if rho > 0.0:
        c = wx / rho
        s = wy / rho
    else:
        c = 1.0
        s = 0.0
    r00 = c * mm[0] - s * mm[3]
    r01 = c * mm[1] - s * mm[4]
    r02 = c * mm[2] - s * mm[5]
    r10 = s * mm[0] + c * mm[3]
    r11 = s * mm[1] + c * mm[4]
    r12 = s * mm[2] + c * mm[5]
    a00 = r00 * c - r01 * s
    a01 = r00 * s + r01 * c
    a02 = r02
    a10 = r10 * c - r11 * s
    a11 = r10 * s + r11 * c
    a12 = r12
    a20 = mm[6] * c - mm[7] * s
    a21 = mm[6] * s + mm[7] * c
    a22 = mm[8]
    # |det M| M^-1 (the integral only needs M^-1 up to a positive factor)
    ok, sg, tm[0], tm[1], tm[2], tm[3], tm[4], tm[5], tm[6], tm[7], tm[8] = signed_adjugate(
        a00, a01, a02, a10, a11, a12, a20, a21, a22)
    if not ok:
        return False, 0.0, 0.0
    tmax = 0.0
    for e in range(9):
        tmax = max(tmax, abs(tm[e]))
    for e in range(9):
        tm[e] /= tmax
    tm[9] = sg  # det(|det| M^-1) has the sign of det M: undo the mirror
    return True, mag, fres


@njit_serial
def ltc_density(tm, wx, wy, wz):
    """``D_M(w)`` (Heitz et al. 2016, eq. 1) of the LTC ``tm (10,)`` (:func:`ltc_lookup`) at
    the unit direction ``w`` (shading frame); 0 where ``M^-1 w`` is below the cosine's horizon.
    ``tm`` is ``M^-1`` up to a positive or negative factor, which cancels: with ``T = s M^-1``,
    ``|M^-1| / |M^-1 w|^3 = |det T| / |T w|^3``."""
    x = tm[0] * wx + tm[1] * wy + tm[2] * wz
    y = tm[3] * wx + tm[4] * wy + tm[5] * wz
    z = tm[6] * wx + tm[7] * wy + tm[8] * wz
    z *= tm[9]
    if z <= 0.0:
        return 0.0
    det = (tm[0] * (tm[4] * tm[8] - tm[5] * tm[7]) - tm[1] * (tm[3] * tm[8] - tm[5] * tm[6])
           + tm[2] * (tm[3] * tm[7] - tm[4] * tm[6]))
    r2 = x * x + y * y + z * z
    return z * abs(det) / (math.pi * r2 * r2)
