"""Height-correlated colour (Heitz et al. 2013, section 5.1): shadowing, the view- and
light-dependent height filtering distribution ``D_h`` and its Gaussian approximation.

A Gaussian microsurface has heights ``N(0, sigma_h^2)`` and, along a direction of azimuth ``phi``,
slopes of std ``sigma_s(phi)``. With the Smith visibility ``V(h, w) = P_h(h)^Lambda(w)`` (eq. 2)
every quantity of the section depends on the directions only through ``Lambda_o``,
``Lambda_i`` and ``L = Lambda_o + Lambda_i``:

* ``V_bar = (1 + Lambda_o) / (1 + L)`` (eq. 13);
* ``D_h(h) = (1 + L) P_h(h)^L p_h(h)`` (eq. 16: the normaliser is ``1 / (1 + L)`` because
  ``P_h(h)`` is uniform under ``p_h``); equivalently ``P_h(h) ~ Beta(1 + L, 1)``;
* its mean and std, approximated by eqs. 17-18 with four constants ``(alpha_mu, beta_mu,
  alpha_sigma, beta_sigma)``: the paper's, or our own fit to the exact moments
  (:func:`fit_height_params`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import erfcx, log_ndtr

from prefilter.validation import (
    as_directions,
    as_float_array,
    as_positive_int,
    as_upper_directions,
    broadcast_batch,
    check_scalar,
)
from prefilter.colormap.table import as_table
from prefilter.errors import PrefilterError
from prefilter.microfacet.beckmann import beckmann_lambda

__all__ = [
    "FIT_LAMBDA_MAX",
    "OWN_PARAMS",
    "PAPER_PARAMS",
    "HeightParams",
    "fit_height_params",
    "filter_height",
    "filter_height_footprint",
    "height_footprint",
    "height_density",
    "height_distribution",
    "height_moments_approx",
    "height_moments_exact",
    "mean_visibility",
    "smith_lambda",
    "smith_lambda_direction",
]


class HeightParams(NamedTuple):
    """Constants of eqs. 17-18."""

    alpha_mu: float
    beta_mu: float
    alpha_sigma: float
    beta_sigma: float


#: The constants printed in the paper (section 5.1).
PAPER_PARAMS = HeightParams(0.39, 4.75, 0.26, 1.13)
#: Our least-squares fit of eqs. 17-18 to the exact moments of eq. 16 over
#: ``L in [0, FIT_LAMBDA_MAX]`` (see :func:`fit_height_params`; rerun it to reproduce).
OWN_PARAMS = HeightParams(0.5120, 2.0948, 0.3036, 1.0135)
#: Upper end of the ``Lambda_o + Lambda_i`` range of the fit (both directions at 89 degrees on a
#: surface of slope std 0.5 give about 22).
FIT_LAMBDA_MAX = 20.0

_INV_SQRT_2PI = 0.3989422804014327


def smith_lambda(cot_theta, sigma_s) -> np.ndarray:
    """Smith's ``Lambda`` of a Gaussian surface (Heitz et al. 2013, eq. 3).

    ``Lambda = sigma_s / (sqrt(2 pi) cot) exp(-cot^2 / (2 sigma_s^2)) - erfc(cot / (sqrt(2)
    sigma_s)) / 2``, with ``cot`` the slope of the direction (``cot theta >= 0``; ``inf`` at
    normal incidence, where ``Lambda = 0``) and ``sigma_s`` the slope std along its azimuth.

    Parameters
    ----------
    cot_theta, sigma_s : array_like, broadcastable shapes (...)

    Returns
    -------
    numpy.ndarray, shape (...)
    """
    try:
        c = np.asarray(cot_theta, dtype=np.float64)  # +inf allowed: normal incidence
    except (TypeError, ValueError):
        raise PrefilterError(f"cot_theta: expected a numeric array, got "
                             f"{type(cot_theta).__name__}") from None
    s = as_float_array(sigma_s, "sigma_s")
    if np.any(np.isnan(c)) or np.any(c <= 0.0):
        raise PrefilterError("cot_theta: expected cotangents > 0 (directions above the surface, "
                             f"not grazing), got min {np.nanmin(c)!r}")
    if np.any(s <= 0.0):
        raise PrefilterError(f"sigma_s: expected slope standard deviations > 0, got {s.min()!r}")
    with np.errstate(over="ignore"):
        return beckmann_lambda(c / (s * np.sqrt(2.0)))


def _slope_std_along(w: np.ndarray, slope_cov: np.ndarray) -> np.ndarray:
    """``sigma_s(phi)``: std of the slope component along the azimuth of ``w``."""
    r = np.hypot(w[..., 0], w[..., 1])
    safe = np.where(r > 0.0, r, 1.0)
    cx = np.where(r > 0.0, w[..., 0] / safe, 1.0)
    cy = np.where(r > 0.0, w[..., 1] / safe, 0.0)
    var = (slope_cov[..., 0, 0] * cx * cx + 2.0 * slope_cov[..., 0, 1] * cx * cy
           + slope_cov[..., 1, 1] * cy * cy)
    return np.sqrt(var)


def _as_cov(slope_cov) -> np.ndarray:
    c = as_float_array(slope_cov, "slope_cov")
    if c.ndim == 0:
        c = c * np.eye(2)  # a scalar is an isotropic variance
    if c.shape[-2:] != (2, 2):
        raise PrefilterError(f"slope_cov: expected a variance or shape (..., 2, 2), got {c.shape}")
    if np.any(c[..., 0, 0] <= 0) or np.any(c[..., 0, 0] * c[..., 1, 1] - c[..., 0, 1] ** 2 <= 0):
        raise PrefilterError("slope_cov: expected positive definite slope covariances")
    return c


def smith_lambda_direction(w, slope_cov) -> np.ndarray:
    """``Lambda(w)`` (eq. 3) of a zero-mean Gaussian surface with slope covariance ``slope_cov``.

    Parameters
    ----------
    w : array_like, shape (..., 3)
        Unit directions above the surface (tangent frame, z = normal).
    slope_cov : array_like, shape (..., 2, 2) or scalar variance

    Returns
    -------
    numpy.ndarray, shape (...)
    """
    w = as_upper_directions(w, "w")
    cov = _as_cov(slope_cov)
    r = np.hypot(w[..., 0], w[..., 1])
    with np.errstate(divide="ignore", over="ignore"):  # r denormal: cot = inf
        cot = np.where(r > 0.0, w[..., 2] / np.where(r > 0, r, 1.0), np.inf)
    return smith_lambda(cot, _slope_std_along(w, cov))


def _as_noise_sigma(noise_sigma) -> np.ndarray:
    sr = as_float_array(noise_sigma, "noise_sigma")
    if np.any(sr < 0.0):
        raise PrefilterError(f"noise_sigma: expected a std >= 0, got min {sr.min()!r}")
    return sr


def _as_lambda(lam, name: str) -> np.ndarray:
    a = as_float_array(lam, name)
    if np.any(a < 0.0):
        raise PrefilterError(f"{name}: expected Lambda values >= 0, got min {a.min()!r}")
    return a


def _as_sigma_h(sigma_h, name: str = "sigma_h") -> np.ndarray:
    sh = as_float_array(sigma_h, name)
    if np.any(sh <= 0.0):
        raise PrefilterError(f"{name}: expected a height std > 0, got min {sh.min()!r}")
    return sh


def mean_visibility(lambda_o, lambda_i) -> np.ndarray:
    """Average light visibility of the visible surface, ``V_bar = (1 + Lo) / (1 + Lo + Li)``
    (Heitz et al. 2013, eq. 13). Shape: broadcast of the inputs."""
    lo = _as_lambda(lambda_o, "lambda_o")
    li = _as_lambda(lambda_i, "lambda_i")
    return (1.0 + lo) / (1.0 + lo + li)


def height_density(h, lam, sigma_h=1.0) -> np.ndarray:
    """The height filtering distribution ``D_h(h) = (1 + L) P_h(h)^L p_h(h)`` (eq. 16), with
    ``L = Lambda_o + Lambda_i``. Shapes broadcast."""
    h = as_float_array(h, "h")
    lam = _as_lambda(lam, "lam")
    sh = as_float_array(sigma_h, "sigma_h")
    if np.any(sh <= 0.0):
        raise PrefilterError(f"sigma_h: expected a height std > 0, got {sh!r}")
    x = h / sh
    return np.exp(np.log1p(lam) + lam * log_ndtr(x) - 0.5 * x * x) * _INV_SQRT_2PI / sh


# quadrature nodes for the exact moments: D_h is unimodal, within [-9, 9] sigma_h for any L < 1e6
_GRID = np.linspace(-9.0, 9.0, 7201)
_LOG_PHI = log_ndtr(_GRID)
_LOG_P = -0.5 * _GRID**2 + np.log(_INV_SQRT_2PI)


def height_moments_exact(lam, sigma_h=1.0) -> tuple[np.ndarray, np.ndarray]:
    """Exact mean ``mu_d`` and std ``sigma_d`` of ``D_h`` (eq. 16, the left sides of eqs. 17-18)
    by quadrature (composite Simpson, 7201 nodes over ``[-9, 9] sigma_h``; error < 1e-10).

    Note that eq. 18 as printed uses the second moment; ``sigma_d`` here is the standard deviation
    ``sqrt(E[h^2] - mu_d^2)``, which is what the Gaussian ``N(mu_d, sigma_d)`` needs.

    Returns
    -------
    mu_d, sigma_d : numpy.ndarray, shape of ``lam`` broadcast with ``sigma_h``
    """
    lam = _as_lambda(lam, "lam")
    sh = as_float_array(sigma_h, "sigma_h")
    if np.any(sh <= 0.0):
        raise PrefilterError(f"sigma_h: expected a height std > 0, got {sh!r}")
    dx = _GRID[1] - _GRID[0]
    wts = np.full(_GRID.size, 2.0)
    wts[1::2] = 4.0
    wts[0] = wts[-1] = 1.0
    wts *= dx / 3.0
    flat = lam.reshape(-1, 1)
    dens = np.exp(np.log1p(flat) + flat * _LOG_PHI + _LOG_P) * wts
    m0 = dens.sum(-1)
    m1 = (dens * _GRID).sum(-1) / m0
    m2 = (dens * _GRID**2).sum(-1) / m0
    mu = m1.reshape(lam.shape)
    sd = np.sqrt(np.maximum(m2 - m1 * m1, 0.0)).reshape(lam.shape)
    return mu * sh, sd * sh


def height_moments_approx(lam, sigma_h=1.0, params: HeightParams = PAPER_PARAMS):
    """Gaussian approximation of ``D_h`` (Heitz et al. 2013, eqs. 17-18):
    ``mu_d = a_mu sigma_h log(b_mu L + 1)``, ``sigma_d = sigma_h / (1 + a_s log(b_s L + 1))``.

    Returns
    -------
    mu_d, sigma_d : numpy.ndarray
    """
    lam = _as_lambda(lam, "lam")
    sh = _as_sigma_h(sigma_h)
    p = as_float_array(tuple(params), "params")
    if p.shape != (4,) or np.any(p < 0.0):
        raise PrefilterError(f"params: expected four constants >= 0 (HeightParams), got {p}")
    a_mu, b_mu, a_s, b_s = (float(x) for x in p)
    mu = a_mu * sh * np.log1p(b_mu * lam)
    sd = sh / (1.0 + a_s * np.log1p(b_s * lam))
    return mu, sd


#: Most grid points of the fits (:func:`fit_height_params`, :func:`height_fit_errors`).
FIT_N_MAX = 1_000_000


def _fit_grid(lam_max, n) -> np.ndarray:
    """``n`` values of ``L`` uniform in ``log(1 + L)`` over ``[0, lam_max]``."""
    top = check_scalar(lam_max, "lam_max", lo=0.0, lo_open=True)
    n = as_positive_int(n, "n", lo=2, hi=FIT_N_MAX)
    return np.expm1(np.linspace(0.0, np.log1p(top), n))


def fit_height_params(lam_max: float = FIT_LAMBDA_MAX, n: int = 400):
    """Least-squares fit of eqs. 17-18 to the exact moments of eq. 16.

    The residuals (in units of ``sigma_h``) are taken at ``n`` values of ``L`` uniformly spaced in
    ``log(1 + L)`` over ``[0, lam_max]`` (dense where the curves bend), ``mu_d`` and ``sigma_d``
    fitted separately (scipy ``least_squares``, start at the paper's constants).

    Returns
    -------
    params : HeightParams
    report : dict
        Max and RMS absolute errors (units of ``sigma_h``) of ``mu_d`` and ``sigma_d`` on the fit
        grid, for the paper's constants and for the fit.
    """
    from scipy.optimize import least_squares

    lam = _fit_grid(lam_max, n)
    mu, sd = height_moments_exact(lam)

    def r_mu(p):
        return p[0] * np.log1p(p[1] * lam) - mu

    def r_sd(p):
        return 1.0 / (1.0 + p[0] * np.log1p(p[1] * lam)) - sd

    a = PAPER_PARAMS
    f_mu = least_squares(r_mu, [a.alpha_mu, a.beta_mu], bounds=([0, 0], [10, 1e3]))
    f_sd = least_squares(r_sd, [a.alpha_sigma, a.beta_sigma], bounds=([0, 0], [10, 1e3]))
    params = HeightParams(*(float(x) for x in (*f_mu.x, *f_sd.x)))
    return params, height_fit_errors({"paper": PAPER_PARAMS, "fit": params}, lam_max, n)


def height_fit_errors(param_sets: dict, lam_max: float = FIT_LAMBDA_MAX, n: int = 400) -> dict:
    """Max / RMS absolute errors (units of ``sigma_h``) of eqs. 17-18 against the exact moments,
    over ``L`` uniform in ``log(1 + L)`` on ``[0, lam_max]``, for each named parameter set."""
    lam = _fit_grid(lam_max, n)
    mu, sd = height_moments_exact(lam)
    out = {}
    for name, p in param_sets.items():
        am, asd = height_moments_approx(lam, 1.0, p)
        out[name] = {
            "params": list(p),
            "mu_max_abs": float(np.abs(am - mu).max()),
            "mu_rms": float(np.sqrt(np.mean((am - mu) ** 2))),
            "sigma_max_abs": float(np.abs(asd - sd).max()),
            "sigma_rms": float(np.sqrt(np.mean((asd - sd) ** 2))),
        }
    return out


def height_distribution(wo, wi, slope_cov, sigma_h=1.0, params: HeightParams | None = None):
    """Gaussian height filtering distribution and mean visibility for a view and a light.

    Parameters
    ----------
    wo, wi : array_like, shape (..., 3)
        View and light directions in the tangent frame.
    slope_cov : array_like, shape (..., 2, 2) or scalar variance
        Slope covariance of the (zero-mean) Gaussian microsurface.
    sigma_h : array_like, shape (...)
        Height std.
    params : HeightParams, optional
        Constants of eqs. 17-18 (default :data:`OWN_PARAMS`).

    Returns
    -------
    mu_d, sigma_d, v_bar : numpy.ndarray, shape (...)
        Eqs. 17, 18 and 13. A light at or below the horizon (``wi_z <= 0``) leaves the surface
        unlit: ``v_bar = 0`` (``Lambda_i = inf``), and ``mu_d, sigma_d`` are those of the view
        alone (finite; the colour they select is multiplied by 0).
    """
    wo = as_upper_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    broadcast_batch(wo=wo.shape[:-1], wi=wi.shape[:-1])
    lit = wi[..., 2] > 0.0
    lam_o = smith_lambda_direction(wo, slope_cov)
    lam_i = np.where(lit, smith_lambda_direction(np.where(lit[..., None], wi, [0.0, 0.0, 1.0]),
                                                 slope_cov), 0.0)
    mu, sd = height_moments_approx(lam_o + lam_i, sigma_h, OWN_PARAMS if params is None else params)
    return mu, sd, np.where(lit, mean_visibility(lam_o, lam_i), 0.0)


def filter_height(table, wo, wi, slope_cov, sigma_h=1.0, *, noise_mean=0.0, noise_sigma=0.0,
                  params: HeightParams | None = None) -> np.ndarray:
    """Filtered height-correlated colour ``C_h_bar = V_bar <C_h, D_h>`` (Heitz et al. 2013,
    eq. 14), optionally for heights offset by a noise of mean ``noise_mean`` and std
    ``noise_sigma`` (section 5.1: ``mu = mu_d + mu_r``, ``sigma^2 = sigma_d^2 + sigma_r^2``).

    ``table`` is a :class:`~prefilter.colormap.table.ColormapTable` over heights. Returns
    ``(..., C)``: it includes the light visibility ``V_bar`` as eq. 14 does.
    """
    as_table(table)
    mu, sd, vbar = height_distribution(wo, wi, slope_cov, sigma_h, params)
    mr = as_float_array(noise_mean, "noise_mean")
    sr = _as_noise_sigma(noise_sigma)
    return vbar[..., None] * table.lookup(mu + mr, np.sqrt(sd * sd + sr * sr))


# -- footprints smaller than the whole surface (our extension) -------------------------------------
#
# Near the camera a pixel sees only part of the height distribution: heights ~ N(mu_fp, sigma_fp^2)
# while the Smith visibility P_h(h)^L still refers to the whole surface. We approximate
# P_h(h)^L ~ Phi(kappa_L h / sigma_h + d_L) (a probit): a Gaussian times a probit is a skew normal,
# whose mass, mean and variance are closed forms, and we choose kappa_L, d_L so that for the whole
# surface (mu_fp = 0, sigma_fp = sigma_h) the mass is eq. 16's 1 / (1 + L) and the mean is the
# exact mu_d. Then V_bar reduces to eq. 13 and the mean to eq. 17's left side; the std is within
# 0.02 sigma_h of the exact sigma_d for L <= 100 (checked in the tests).

_PROBIT_T = np.linspace(np.log(1e-4), np.log(1e4), 161)  # grid in log L


def _probit_table():
    """``(kappa_L, d_L)`` on :data:`_PROBIT_T` (computed once from the exact moments)."""
    global _PROBIT
    try:
        return _PROBIT
    except NameError:
        pass
    from scipy.special import ndtri

    lam = np.exp(_PROBIT_T)
    mu, _ = height_moments_exact(lam)
    z0 = ndtri(1.0 / (1.0 + lam))
    tau = _mills(z0) / mu  # sqrt(1 + s^2) with s the probit's scale
    s = np.sqrt(np.maximum(tau * tau - 1.0, 1e-12))
    _PROBIT = (1.0 / s, z0 * tau / s)
    return _PROBIT


def _mills(z):
    """``phi(z) / Phi(z)``, stable for z << 0."""
    return np.sqrt(2.0 / np.pi) / erfcx(-z / np.sqrt(2.0))


def _probit(lam):
    kappa, d = _probit_table()
    t = np.log(np.maximum(lam, 1e-300))
    k = np.interp(t, _PROBIT_T, kappa)
    dd = np.interp(t, _PROBIT_T, d)
    # below the grid the tilt vanishes (kappa -> 0, d -> +inf); above it L is far beyond use
    small = lam < np.exp(_PROBIT_T[0])
    return np.where(small, 0.0, k), np.where(small, 40.0, dd)


def height_footprint(mu_fp, sigma_fp, lambda_o, lambda_i, sigma_h=1.0):
    """Height filtering distribution over a footprint whose heights are ``N(mu_fp, sigma_fp^2)``
    on a surface of height std ``sigma_h`` (our extension of eqs. 13-17, see the comment above).

    Returns
    -------
    mean, std, v_bar : numpy.ndarray, broadcast shape
        Mean and std of ``D_h`` (a Gaussian approximation) and the footprint's mean light
        visibility ``E[V_o V_i] / E[V_o]``.
    """
    from scipy.special import log_ndtr as _lndtr

    m = as_float_array(mu_fp, "mu_fp")
    sf = as_float_array(sigma_fp, "sigma_fp")
    sh = as_float_array(sigma_h, "sigma_h")
    lo = _as_lambda(lambda_o, "lambda_o")
    li = _as_lambda(lambda_i, "lambda_i")
    if np.any(sf < 0) or np.any(sh <= 0):
        raise PrefilterError("sigma_fp, sigma_h: expected sigma_fp >= 0 and sigma_h > 0")
    x, v = m / sh, (sf / sh) ** 2

    def tilt(lam):
        k, d = _probit(lam)
        r = np.sqrt(1.0 + k * k * v)
        z = (k * x + d) / r
        return z, k, r

    z, k, r = tilt(lo + li)
    zo, _, _ = tilt(lo)
    lam_z = _mills(z)
    mean = x + k * v * lam_z / r
    var = np.maximum(v - (k * v / r) ** 2 * lam_z * (z + lam_z), 0.0)
    v_bar = np.exp(_lndtr(z) - _lndtr(zo))
    return mean * sh, np.sqrt(var) * sh, v_bar


def filter_height_footprint(table, mu_fp, sigma_fp, lambda_o, lambda_i, sigma_h=1.0):
    """``V_bar <C_h, D_h>`` over a footprint (eq. 14 with :func:`height_footprint`),
    ``(..., C)``."""
    as_table(table)
    mean, std, v_bar = height_footprint(mu_fp, sigma_fp, lambda_o, lambda_i, sigma_h)
    return v_bar[..., None] * table.lookup(mean, std)
