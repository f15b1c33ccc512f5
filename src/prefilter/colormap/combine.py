"""Combining texture-, height- and slope-correlated colour maps (Heitz et al. 2013, section 6).

Heights and slopes of a Gaussian surface are uncorrelated, and ``C_0`` depends on neither, so the
integrand of eq. 1 factorises term by term. With the filtered colours ``C0_bar`` (eq. 8),
``Ch_bar`` (eq. 14, which already contains the light visibility ``V_bar``), ``Cs_bar`` (eq. 20)
and ``V_bar`` (eq. 13):

* linear ``C = k0 C0 + k1 Ch + k2 Cs``:
  ``I = L rho [k0 C0_bar V_bar + k1 Ch_bar + k2 Cs_bar V_bar]``;
* product ``C = C0 Ch Cs``:  ``I = L rho C0_bar Ch_bar Cs_bar`` (the paper prints it without the
  filtered reflectance ``rho``; with ``rho = 1`` they agree).
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_float_array, broadcast_batch
from prefilter.errors import PrefilterError

__all__ = ["combine_linear", "combine_product"]


def combine_linear(kappa, c0, ch, cs, v_bar, *, l_bar=1.0, rho_bar=1.0) -> np.ndarray:
    """``I = L_bar rho_bar [k0 C0_bar V_bar + k1 Ch_bar + k2 Cs_bar V_bar]`` (section 6).

    Parameters
    ----------
    kappa : array_like, shape (3,)
        Weights ``(k0, k1, k2)``.
    c0, ch, cs : array_like, shape (..., C)
        Filtered texture, height (including ``V_bar``, as eq. 14) and slope colours.
    v_bar : array_like, shape (...)
        Mean light visibility (eq. 13).
    l_bar, rho_bar : array_like, shape (...)
        Filtered incident radiance and reflectance (grey; a colour axis is appended).

    Returns
    -------
    numpy.ndarray, shape (..., C)
    """
    k = as_float_array(kappa, "kappa")
    if k.shape != (3,):
        raise PrefilterError(f"kappa: expected three weights (k0, k1, k2), got shape {k.shape}")
    c0 = as_float_array(c0, "c0", ndim_min=1)
    ch = as_float_array(ch, "ch", ndim_min=1)
    cs = as_float_array(cs, "cs", ndim_min=1)
    v = as_float_array(v_bar, "v_bar")[..., None]
    light = _light(l_bar, rho_bar)
    broadcast_batch(c0=c0.shape, ch=ch.shape, cs=cs.shape, v_bar=v.shape, light=np.shape(light))
    return light * (k[0] * c0 * v + k[1] * ch + k[2] * cs * v)


def combine_product(c0, ch, cs, *, l_bar=1.0, rho_bar=1.0) -> np.ndarray:
    """``I = L_bar rho_bar C0_bar Ch_bar Cs_bar`` for ``C = C0 Ch Cs`` (section 6), ``(..., C)``."""
    c0 = as_float_array(c0, "c0", ndim_min=1)
    ch = as_float_array(ch, "ch", ndim_min=1)
    cs = as_float_array(cs, "cs", ndim_min=1)
    light = _light(l_bar, rho_bar)
    broadcast_batch(c0=c0.shape, ch=ch.shape, cs=cs.shape, light=np.shape(light))
    return light * c0 * ch * cs


def _light(l_bar, rho_bar) -> np.ndarray:
    lb = as_float_array(l_bar, "l_bar")
    rb = as_float_array(rho_bar, "rho_bar")
    lb = lb[..., None] if lb.ndim else lb
    rb = rb[..., None] if rb.ndim else rb
    return lb * rb
