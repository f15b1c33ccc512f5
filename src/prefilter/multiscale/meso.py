"""Meso-scale roughness from the length of an averaged normal (Tao et al. 2021, eqs. 2-5).

A footprint's normals are modelled by the isotropic LTC ``M = diag(a, a, 1)`` (eq. 2). Its mean
resultant length (eq. 4) has the closed form (``equations.md`` 4, integrated analytically)::

    r(a) = 2 int_0^1 u^2 / sqrt(a^2 (1 - u^2) + u^2) du
         = (1 - a^2 artanh(k) / k) / k^2,   k = sqrt(1 - a^2)        (a < 1)
         = (a^2 arctan(q) / q - 1) / q^2,   q = sqrt(a^2 - 1)        (a > 1)
         = sum_{n >= 0} 2 s^n / ((2n + 1)(2n + 3)),  s = 1 - a^2       (series, |s| small)

decreasing from ``r(0) = 1`` (all normals equal) to ``r(1) = 2/3`` (cosine-distributed normals).
The same LTC is exactly the GGX distribution of normals weighted by projected area,
``D_GGX(m; a) m_z`` (substitute ``M^-1`` in eq. 1), so ``a`` is a GGX roughness.

The paper inverts eq. 4 with a rational fit (eq. 5, ``variant="paper"``). The default
(``variant="exact"``) interpolates the exact inverse: bisection on the closed form at 4097 nodes
uniform in ``x = sqrt(3 (1 - r))`` (the variable in which ``a(x)`` is nearly linear), linearly
interpolated; its error against the exact inverse is below 1e-7 (``tests/multiscale``).
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError

__all__ = ["PAPER_EQ5", "alpha_meso", "alpha_meso_exact", "mean_resultant_length"]

#: Tao et al. 2021, eq. 5: numerator (r^4 .. r^0) and denominator (r^3 .. r^0) coefficients.
PAPER_EQ5 = ((1.629, 17.05, -18.96, -23.37, 23.65), (1.0, -28.07, 31.1, -3.545))

#: r(1): the mean resultant length of the clamped cosine; smaller lengths clamp to alpha = 1.
R_COSINE = 2.0 / 3.0

_SERIES_S = 0.25  # |1 - a^2| below this: the series (closed forms cancel catastrophically)
_SERIES_N = 30  # 0.25^30 ~ 1e-18


def mean_resultant_length(alpha) -> np.ndarray:
    """Mean resultant length ``|E[b]|`` of the normals of ``LTC(diag(alpha, alpha, 1))``.

    Tao et al. 2021, eq. 4, evaluated in closed form (module docstring).

    Parameters
    ----------
    alpha : array_like, shape (...)
        Meso-scale (or GGX) roughness, ``>= 0``.

    Returns
    -------
    numpy.ndarray, shape (...)
        In ``(0, 1]``; ``1`` at ``alpha = 0``, ``2/3`` at ``alpha = 1``.
    """
    a = as_float_array(alpha, "alpha")
    if np.any(a < 0.0):
        raise PrefilterError(f"alpha: expected values >= 0, got minimum {a.min():.4g}")
    return _mrl(a)


def _mrl(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(over="ignore"):  # a > 1e154: s = -inf only selects the branch
        s = 1.0 - a * a
    out = np.empty_like(a)
    near = np.abs(s) < _SERIES_S
    lo = (~near) & (s > 0.0)
    hi = (~near) & (s < 0.0)
    if np.any(near):
        sn = s[near]
        acc = np.zeros_like(sn)
        for n in range(_SERIES_N - 1, -1, -1):  # Horner
            acc = acc * sn + 2.0 / ((2 * n + 1) * (2 * n + 3))
        out[near] = acc
    if np.any(lo):
        k = np.sqrt(s[lo])
        al = a[lo]
        # artanh(k) = log((1 + k) / a); a^2 log(1/a) -> 0 at a = 0
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(al > 0.0, al * al * (np.log1p(k) - np.log(al)), 0.0)
        out[lo] = (1.0 - t / k) / (k * k)
    if np.any(hi):
        # (a^2 atan(q) / q - 1) / q^2 with q = sqrt(a^2 - 1), as ((a/q)^2 atan(q) - 1/q) / q:
        # no a^2 or q^2 to overflow for huge a (the limit is pi / (2 a))
        ah = a[hi]
        ratio = 1.0 / np.sqrt(1.0 - (1.0 / ah) ** 2)  # a / q
        q = ah / ratio
        out[hi] = (ratio * ratio * np.arctan(q) - 1.0 / q) / q
    return out


def alpha_meso_exact(r, *, iterations: int = 60) -> np.ndarray:
    """The exact inverse of eq. 4 by bisection (slow reference; :func:`alpha_meso` interpolates
    it). ``r (...)`` in ``[2/3, 1]``; returns ``alpha (...)`` in ``[0, 1]`` to ``2^-iterations``."""
    r = as_float_array(r, "r")
    iterations = as_positive_int(iterations, "iterations")
    lo = np.zeros_like(r)
    hi = np.ones_like(r)
    for _ in range(iterations):  # r(a) is decreasing
        mid = 0.5 * (lo + hi)
        above = _mrl(mid) > r
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return 0.5 * (lo + hi)


_X_NODES = np.linspace(0.0, 1.0, 4097)
_A_NODES = alpha_meso_exact(1.0 - _X_NODES**2 / 3.0)
_A_NODES[0], _A_NODES[-1] = 0.0, 1.0


def _alpha_from_r(r: np.ndarray) -> np.ndarray:
    x = np.sqrt(np.clip(3.0 * (1.0 - r), 0.0, 1.0))
    return np.interp(x, _X_NODES, _A_NODES)


def _paper_eq5(r: np.ndarray) -> np.ndarray:
    (n4, n3, n2, n1, n0), (d3, d2, d1, d0) = PAPER_EQ5
    num = (((n4 * r + n3) * r + n2) * r + n1) * r + n0
    den = ((d3 * r + d2) * r + d1) * r + d0
    return num / den


def alpha_meso(r, variant: str = "exact") -> np.ndarray:
    """Meso-scale roughness from the mean resultant length ``r`` of a footprint's normals.

    Tao et al. 2021, eq. 5 (``variant="paper"``: their rational fit of the inverse of eq. 4) or
    the exact inverse of eq. 4 (``"exact"``, default; interpolated, error < 1e-7).

    Parameters
    ----------
    r : array_like, shape (...)
        Length of the averaged (unnormalised) normal, in ``[0, 1]`` (up to ``1 + 1e-6``).
    variant : {"exact", "paper"}

    Returns
    -------
    numpy.ndarray, shape (...)
        ``alpha_meso`` clamped to ``[0, 1]`` (``r <= 2/3`` gives 1, the paper's clamp).
    """
    r = as_float_array(r, "r")
    if np.any((r < 0.0) | (r > 1.0 + 1e-6)):
        raise PrefilterError(f"r: expected lengths in [0, 1], got range [{r.min():.6g}, "
                             f"{r.max():.6g}]")
    if variant == "exact":
        return _alpha_from_r(r)
    if variant == "paper":
        rc = np.clip(r, R_COSINE, 1.0)
        # eq. 5 crosses zero just below r = 1 and leaves [0, 1] near 2/3; the paper clamps
        return np.clip(_paper_eq5(rc), 0.0, 1.0)
    raise PrefilterError(f"variant: expected 'exact' or 'paper', got {variant!r}")
