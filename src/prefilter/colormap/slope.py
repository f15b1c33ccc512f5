"""Slope-correlated colour (Heitz et al. 2013, section 5.2): the view-dependent slope filtering
distribution and the filtering of a 2D slope colour map with it.

The derivation is in ``docs/slope-filtering.md``. A surface element of slope ``s`` (normal
``(-s_x, -s_y, 1) / sqrt(1 + |s|^2)``) and unit macro-area has the projected area
``max(0, w_z - s . (w_x, w_y))`` towards ``w``, so eq. 20's normalised distribution is

    D_s(s) = max(0, t(s)) N(s; mu, Sigma) / E[max(0, t)],   t(s) = w_z - s . (w_x, w_y),

a ramp times a Gaussian. ``t`` is Gaussian (mean ``m_t``, variance ``v_t = a^T Sigma a`` with
``a = -(w_x, w_y)``), and writing ``s = mu + Sigma a (t - m_t) / v_t + r`` with ``r`` independent
of ``t`` gives the moments in closed form (``alpha = m_t / sqrt(v_t)``, ``lambda = phi(alpha) /
Phi(alpha)``, ``m_k = E[u^k 1{u>0}] / Phi(alpha)`` for ``u ~ N(alpha, 1)``):

    E_D[s]   = mu + Sigma a / sqrt(v_t) / (alpha + lambda)
    Cov_D[s] = Sigma - (Sigma a a^T Sigma / v_t) (1 - Var_w[u]),  Var_w[u] = m_3/m_1 - (m_2/m_1)^2.

The Gaussian with these moments approximates ``D_s`` (the paper's choice). A 2D Gaussian filter of
a general covariance is evaluated from a stack of *isotropically* pre-blurred copies of the slope
colour map (:class:`SlopeColormapTable`): the covariance splits exactly into ``lambda_2 I +
(lambda_1 - lambda_2) e_1 e_1^T`` (its eigenvalues / major eigenvector), so a lookup reads the
stack at std ``sqrt(lambda_2)`` (trilinear) and integrates the remaining 1D Gaussian along
``e_1`` with a few Gauss-Hermite taps, as anisotropic texture filtering does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erfcx

from prefilter.validation import (
    SLOPE_MAX,
    as_float_array,
    as_positive_int,
    as_upper_directions,
    broadcast_batch,
    check_scalar,
)
from prefilter.colormap.table import gaussian_operator
from prefilter.errors import PrefilterError

__all__ = ["SlopeColormapTable", "filter_slope", "slope_density",
           "slope_distribution", "slope_prefilter_table"]

_SQRT_2_OVER_PI = 0.7978845608028654
#: Most Gauss-Hermite taps of :meth:`SlopeColormapTable.lookup` (beyond ~100 the outer weights
#: underflow and the node computation grows as n^2).
N_TAPS_MAX = 100


def _as_mean_cov(mean, cov):
    mu = as_float_array(mean, "mean", ndim_min=1, last_dim=2)
    c = as_float_array(cov, "cov", ndim_min=2)
    if c.shape[-2:] != (2, 2):
        raise PrefilterError(f"cov: expected shape (..., 2, 2), got {c.shape}")
    if np.any(np.abs(c[..., 0, 1] - c[..., 1, 0])
              > 1e-9 * (np.abs(c[..., 0, 0]) + np.abs(c[..., 1, 1])) + 1e-300):
        raise PrefilterError("cov: expected symmetric 2x2 covariances, got different "
                             "off-diagonal entries")
    broadcast_batch(mean=mu.shape[:-1], cov=c.shape[:-2])
    tr = c[..., 0, 0] + c[..., 1, 1]
    disc = np.sqrt(0.25 * (c[..., 0, 0] - c[..., 1, 1]) ** 2 + c[..., 0, 1] * c[..., 1, 0])
    # rank-deficient covariances come out of arithmetic with slightly negative eigenvalues
    if np.any(0.5 * tr - disc < -1e-9 * np.abs(tr) - 1e-15):
        raise PrefilterError("cov: expected positive semi-definite 2x2 covariances")
    return mu, c


def _ramp_weight(w, mu, cov):
    """``a = -(w_x, w_y)``, ``m_t``, ``v_t`` of the ramp variable ``t = w_z + a . s``."""
    a = -w[..., :2]
    m_t = w[..., 2] + np.einsum("...i,...i->...", a, mu)
    sa = np.einsum("...ij,...j->...i", cov, a)
    v_t = np.einsum("...i,...i->...", a, sa)
    return a, m_t, sa, v_t


def slope_distribution(wo, mean, cov) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the view-dependent slope filtering distribution ``D_s`` (Heitz et al.
    2013, eq. 20; closed form derived in ``docs/slope-filtering.md``).

    Parameters
    ----------
    wo : array_like, shape (..., 3)
        View direction in the tangent frame (z = mean-surface normal).
    mean : array_like, shape (..., 2)
        Mean slope over the footprint.
    cov : array_like, shape (..., 2, 2)
        Slope covariance over the footprint.

    Returns
    -------
    mean_d : numpy.ndarray, shape (..., 2)
    cov_d : numpy.ndarray, shape (..., 2, 2)
    """
    w = as_upper_directions(wo, "wo")
    mu, c = _as_mean_cov(mean, cov)
    batch = broadcast_batch(wo=w.shape[:-1], mean=mu.shape[:-1], cov=c.shape[:-2])
    w = np.broadcast_to(w, batch + (3,))
    mu = np.broadcast_to(mu, batch + (2,))
    c = np.broadcast_to(c, batch + (2, 2))
    _, m_t, sa, v_t = _ramp_weight(w, mu, c)
    deg = v_t <= 1e-300  # t does not vary: D_s is the slope Gaussian itself
    sd = np.sqrt(np.where(deg, 1.0, v_t))
    # alpha < -37 only for slope distributions lying almost entirely behind the view
    alpha = np.maximum(m_t / sd, -37.0)
    lam = _SQRT_2_OVER_PI / erfcx(-alpha / np.sqrt(2.0))  # phi(alpha) / Phi(alpha), stably
    m1 = alpha + lam
    m2 = alpha * alpha + 1.0 + alpha * lam
    pos = alpha >= 0.0
    ap = np.where(pos, 1.0, alpha)  # alpha**3 overflows (and m3/m1 - (m2/m1)^2 cancels) for
    m3 = ap**3 + 3.0 * ap + (ap * ap + 2.0) * lam  # large alpha: there use the identity
    # m3 m1 - m2^2 = (alpha + lam)(alpha + 2 lam) - 1, i.e. var = 1 + lam / m1 - 1 / m1^2
    var_u = np.where(pos, 1.0 + lam / m1 - 1.0 / (m1 * m1), m3 / m1 - (m2 / m1) ** 2)
    var_u = np.clip(var_u, 0.0, 1.0)
    shift = np.where(deg, 0.0, 1.0 / (sd * m1))
    mean_d = mu + sa * shift[..., None]
    shrink = np.where(deg, 0.0, (1.0 - var_u) / np.where(deg, 1.0, v_t))
    cov_d = c - sa[..., :, None] * sa[..., None, :] * shrink[..., None, None]
    return mean_d, cov_d


def slope_density(s, wo, mean, cov) -> np.ndarray:
    """The exact ``D_s(s) = max(0, w_z - s . w_xy) N(s; mu, Sigma) / E[max(0, t)]`` (eq. 20),
    shape ``(...)`` (``s (..., 2)``; ``Sigma`` must be positive definite): the visible-slope
    density of the non-centred Beckmann lobe (:class:`prefilter.microfacet.Beckmann`)."""
    from prefilter.microfacet import Beckmann

    w = as_upper_directions(wo, "wo")
    mu, c = _as_mean_cov(mean, cov)
    s = as_float_array(s, "s", ndim_min=1, last_dim=2)
    lobe = Beckmann(mu, c)
    ramp = np.maximum(0.0, w[..., 2] - np.einsum("...i,...i->...", s, w[..., :2]))
    return ramp * lobe.P22(s) / lobe.projected_area(w)


def _sym_eig(c):
    """Eigenvalues ``l1 >= l2 >= 0`` and major unit eigenvector of symmetric 2x2 ``c``."""
    p, q, r = c[..., 0, 0], 0.5 * (c[..., 0, 1] + c[..., 1, 0]), c[..., 1, 1]
    mid = 0.5 * (p + r)
    disc = np.sqrt(np.maximum(0.25 * (p - r) ** 2 + q * q, 0.0))
    l1, l2 = mid + disc, np.maximum(mid - disc, 0.0)
    v1 = np.stack([q, l1 - p], -1)
    v2 = np.stack([l1 - r, q], -1)
    v = np.where((np.sum(v1 * v1, -1) >= np.sum(v2 * v2, -1))[..., None], v1, v2)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    v = np.where(n > 0, v / np.where(n > 0, n, 1.0), np.array([1.0, 0.0]))
    return l1, l2, v


@dataclass(frozen=True)
class SlopeColormapTable:
    """A slope colour map ``C(s_x, s_y)`` and its isotropically pre-blurred stack.

    Attributes
    ----------
    stack : numpy.ndarray, shape (n_levels, n, n, C)
        ``stack[k]`` is the map convolved with ``N(0, sigma_k^2 I)``, ``sigma_k = sigma_max k /
        (n_levels - 1)``; ``stack[k, i, j]`` sits at slope ``(x_j, y_i)``, the texel centres of
        ``[-extent, extent]`` (row = s_y, column = s_x). Outside, the map is clamped.
    extent : float
    sigma_max : float
    """

    stack: np.ndarray
    extent: float
    sigma_max: float

    @property
    def n(self) -> int:
        return self.stack.shape[1]

    def _trilinear(self, s, sigma):
        n, nl, e = self.n, self.stack.shape[0], self.extent
        # clamped map: saturate before the int64 cast (|s| > 1e17 wrapped to the wrong edge)
        x = np.clip((s[..., 0] + e) / (2 * e) * n - 0.5, -1.0, float(n))
        y = np.clip((s[..., 1] + e) / (2 * e) * n - 0.5, -1.0, float(n))
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[..., None], (y - y0)[..., None]
        i0 = np.clip(y0.astype(np.int64), 0, n - 1)
        i1 = np.clip(y0.astype(np.int64) + 1, 0, n - 1)
        j0 = np.clip(x0.astype(np.int64), 0, n - 1)
        j1 = np.clip(x0.astype(np.int64) + 1, 0, n - 1)
        z = np.clip(sigma / self.sigma_max, 0.0, 1.0) * (nl - 1)
        k0 = np.minimum(np.floor(z).astype(np.int64), nl - 2)
        fz = (z - k0)[..., None]
        out = 0.0
        for k, wk in ((k0, 1.0 - fz), (k0 + 1, fz)):
            t = self.stack
            top = t[k, i0, j0] * (1 - fx) + t[k, i0, j1] * fx
            bot = t[k, i1, j0] * (1 - fx) + t[k, i1, j1] * fx
            out = out + wk * (top * (1 - fy) + bot * fy)
        return out

    def lookup(self, mean, cov, n_taps: int = 7) -> np.ndarray:
        """``<C, N(mean, cov)>``: stack at the minor std, Gauss-Hermite taps along the major axis.

        Parameters
        ----------
        mean : array_like, shape (..., 2)
        cov : array_like, shape (..., 2, 2)
        n_taps : int
            Gauss-Hermite nodes along the major axis (1 = isotropic approximation), at most
            :data:`N_TAPS_MAX`.

        Returns
        -------
        numpy.ndarray, shape (..., C)
        """
        mu, c = _as_mean_cov(mean, cov)
        batch = np.broadcast_shapes(mu.shape[:-1], c.shape[:-2])
        mu, c = np.broadcast_to(mu, batch + (2,)), np.broadcast_to(c, batch + (2, 2))
        l1, l2, e1 = _sym_eig(c)
        nt = as_positive_int(n_taps, "n_taps", hi=N_TAPS_MAX)
        x, wts = np.polynomial.hermite_e.hermegauss(nt)
        wts = wts / wts.sum()
        r = np.sqrt(np.maximum(l1 - l2, 0.0))[..., None] * e1
        s_iso = np.sqrt(l2)
        out = 0.0
        for xk, wk in zip(x, wts):  # a handful of taps, each vectorised over all pixels
            out = out + wk * self._trilinear(mu + xk * r, s_iso)
        return out

    def naive(self, mean) -> np.ndarray:
        """``C(mean)``, shape ``(..., C)``."""
        mu = as_float_array(mean, "mean", ndim_min=1, last_dim=2)
        return self._trilinear(mu, np.zeros(mu.shape[:-1]))


def slope_prefilter_table(colormap, extent: float = 1.0, sigma_max: float = 0.5,
                          n_levels: int = 32) -> SlopeColormapTable:
    """Stack of a 2D slope colour map blurred by isotropic Gaussians of std ``0..sigma_max``.

    Each level is the separable closed-form convolution of the bilinear interpolant (the 1D
    operator of :func:`prefilter.colormap.table.gaussian_operator` applied along both axes, edges
    clamped), so the stack is exact.

    Parameters
    ----------
    colormap : array_like, shape (n, n, C) or (n, n)
        Colours at the texel centres of ``[-extent, extent]^2`` (row = s_y, column = s_x).
    extent, sigma_max : float
        Slope half-range and largest isotropic std (slope units).
    n_levels : int

    Returns
    -------
    SlopeColormapTable
    """
    c = as_float_array(colormap, "colormap", ndim_min=2)
    if c.ndim == 2:
        c = c[..., None]
    if c.ndim != 3 or c.shape[0] != c.shape[1] or c.shape[0] < 2:
        raise PrefilterError(f"colormap: expected a square (n, n, C) slope colour map, got "
                             f"shape {c.shape}")
    e = check_scalar(extent, "extent", lo=0.0, hi=SLOPE_MAX, lo_open=True)
    smax = check_scalar(sigma_max, "sigma_max", lo=0.0, lo_open=True)
    nl = as_positive_int(n_levels, "n_levels", lo=2)
    n = c.shape[0]
    levels = []
    for s in np.linspace(0.0, smax, nl):
        op = gaussian_operator(n, s / (2.0 * e), "clamp")
        levels.append(np.einsum("ik,jl,klc->ijc", op, op, c, optimize=True))
    stack = np.stack(levels)
    stack[0] = c
    return SlopeColormapTable(stack, e, smax)


def filter_slope(table: SlopeColormapTable, wo, mean, cov, n_taps: int = 7) -> np.ndarray:
    """Filtered slope-correlated colour ``C_s_bar(wo) = <C_s, D_s>`` (Heitz et al. 2013, eq. 20)
    with ``D_s`` replaced by the Gaussian of its exact moments. Shape ``(..., C)``."""
    from prefilter.colormap.table import as_table

    as_table(table, SlopeColormapTable)
    as_positive_int(n_taps, "n_taps", hi=N_TAPS_MAX)  # before the distribution's work
    m, c = slope_distribution(wo, mean, cov)
    return table.lookup(m, c, n_taps)

