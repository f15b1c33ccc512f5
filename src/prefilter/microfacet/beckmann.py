"""Non-centred anisotropic Beckmann: Gaussian slopes with mean ``mu`` and covariance ``Sigma``.

The slope of a microfacet normal ``m`` is ``s = (-mx/mz, -my/mz)`` and ``P22(s) = N(s; mu, Sigma)``,
so ``D(m) = P22(s(m)) / mz^4`` (LEADR supplemental 3.1). A non-zero mean slope tilts the mean
surface: its normal is ``n_bar ~ (-mu_x, -mu_y, 1)`` and its projected area per unit geometric
area is ``A(w) = w_z - mu . w_xy``; Smith's identity then reads
``integral G1(w) max(0, w.m) D(m) dm = A(w)`` (LEADR supplemental eq. 9).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from prefilter.jit import njit_inline, njit_serial
from prefilter.validation import as_directions, as_float_array, as_roughness, as_uniform
from prefilter.errors import PrefilterError
from prefilter.microfacet.base import MicrofacetModel

_SQRT2 = np.sqrt(2.0)
_SQRT_PI = np.sqrt(np.pi)
_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)


@njit_inline
def beckmann_lambda_jit(a):
    """Smith ``Lambda = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2`` for Gaussian slopes and one
    ``a > 0`` (Smith 1967; Walter et al. 2007 eq. 27; LEADR supplemental 3.2), in kernels and
    behind :func:`beckmann_lambda`. The difference loses about ``2 a^2`` ulps to cancellation
    (1e-13 relative at a = 10); rounding below 0 gives 0, and both terms underflow to the exact
    limit 0 beyond a ~ 27 and at ``a = +inf``."""
    return max(0.5 * (math.exp(-a * a) / (a * _SQRT_PI) - math.erfc(a)), 0.0)


@njit_serial
def _beckmann_lambda_kernel(a, out):  # pragma: no cover - compiled
    for i in range(a.size):
        out[i] = beckmann_lambda_jit(a[i])


def beckmann_lambda(a) -> np.ndarray:
    """Exact Smith ``Lambda(a)`` for Gaussian slopes, ``(...)`` (:func:`beckmann_lambda_jit`).

    ``a <= 0`` means the direction sees only the back of the mean surface: ``Lambda = +inf``
    (``G1 = 0``), the limit of ``Lambda ~ 1 / (2 a sqrt(pi))`` as ``a -> 0+``. ``a = +inf``
    (normal incidence) gives 0. Never NaN for non-NaN input.
    """
    a = np.asarray(a, dtype=np.float64)
    pos = a > 0.0
    ap = np.ascontiguousarray(np.where(pos, a, 1.0).reshape(-1))
    lam = np.empty_like(ap)
    _beckmann_lambda_kernel(ap, lam)
    return np.where(pos, lam.reshape(a.shape), np.inf)


def smith_lambda_walter(a) -> np.ndarray:
    """Walter et al.'s rational fit of :func:`beckmann_lambda` (LEADR supplemental 3.2).

    ``(1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2)`` for ``0 < a < 1.6``, 0 above, ``+inf``
    for ``a <= 0`` (as the exact form). Max error over ``a`` in (0, 10]: see docs/microfacet.md.
    """
    a = np.asarray(a, dtype=np.float64)
    mid = (a > 0.0) & (a < 1.6)
    am = np.where(mid, a, 1.0)
    fit = (1.0 - 1.259 * am + 0.396 * am * am) / (3.535 * am + 2.181 * am * am)
    return np.where(a <= 0.0, np.inf, np.where(mid, fit, 0.0))


def slope_pdf(dx, dy, sxx, syy, sxy) -> np.ndarray:
    """Gaussian slope density ``P22 = N(d; 0, [[sxx, sxy], [sxy, syy]])`` of slope offsets
    ``d = s - mu = (dx, dy)`` (LEADR supplemental 3.1), arrays broadcast together."""
    det = sxx * syy - sxy * sxy
    q = (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det
    return np.exp(-0.5 * q) / (2.0 * np.pi * np.sqrt(det))


def _log_ramp_cdf(x, a):
    """``log(a Phi(x) + phi(x))`` for ``x <= a``: the unnormalised CDF of ``(a - x) phi(x)``.

    For ``x < 0`` it is ``log phi(x) + log(1 + a R(-x))`` with Mills' ratio
    ``R(y) = sqrt(pi/2) erfcx(y / sqrt 2)``, which neither underflows nor overflows; for ``x >= 0``
    (only when ``a > 0``) both terms of ``a Phi(x) + phi(x)`` are positive and O(1).
    """
    neg = x < 0.0
    xn = np.where(neg, x, -1.0)
    mills = np.sqrt(np.pi / 2) * special.erfcx(-xn / _SQRT2)
    lo = -0.5 * xn * xn - _LOG_SQRT_2PI + np.log(np.maximum(1.0 + a * mills, 1e-300))
    xp = np.where(neg, 0.0, x)
    hi = np.log(np.maximum(a * special.ndtr(xp) + np.exp(-0.5 * xp * xp - _LOG_SQRT_2PI), 1e-300))
    return np.where(neg, lo, hi)


def _ramp_cdf(x, a):
    """CDF ``(a Phi(x) + phi(x)) / (a Phi(a) + phi(a))`` of the density ``~ (a - x) phi(x)``."""
    big = a > 1e12
    ab = np.where(big, 1.0, a)
    xb = np.minimum(x, ab)
    with np.errstate(invalid="ignore"):
        f = np.exp(_log_ramp_cdf(xb, ab) - _log_ramp_cdf(ab, ab))
    return np.where(big, special.ndtr(x), f)


def _sample_ramp(a, u, *, tol: float = 1e-12, max_iter: int = 200):
    """Invert the CDF ``(a Phi(x) + phi(x)) / (a Phi(a) + phi(a))`` on ``x <= a`` at ``u``.

    The density ``(a - x) phi(x)`` is the visible-slope density along the view's azimuth (a
    Gaussian times the projected-area ramp). Newton on the log CDF with a bisection safeguard;
    converges to ``tol`` in x. ``a = +inf`` gives a standard normal.
    """
    a, u = np.broadcast_arrays(np.asarray(a, float), np.asarray(u, float))
    a = a.ravel()
    u = np.clip(u.ravel(), 1e-300, 1.0)
    x = np.empty_like(a)
    inf = a > 1e12
    x[inf] = special.ndtri(np.minimum(u[inf], 1.0 - 2.0**-53))
    idx = np.flatnonzero(~inf)
    if idx.size:
        aa, uu = a[idx], u[idx]
        target = np.log(uu) + _log_ramp_cdf(aa, aa)
        lo = np.minimum(aa, 0.0) - 40.0
        hi = aa.copy()
        # Start from the a -> inf limit, kept strictly inside the bracket.
        xx = np.clip(special.ndtri(uu * special.ndtr(aa)), lo + 1e-3, aa - 1e-9 * (1 + abs(aa)))
        xx = np.where(np.isfinite(xx), xx, 0.5 * (lo + hi))
        active = np.arange(idx.size)
        for _ in range(max_iter):
            xa, aa_a = xx[active], aa[active]
            lg = _log_ramp_cdf(xa, aa_a)
            h = lg - target[active]
            lo[active] = np.where(h < 0.0, xa, lo[active])
            hi[active] = np.where(h >= 0.0, xa, hi[active])
            # d/dx log g = (a - x) phi(x) / g(x)
            dlg = (aa_a - xa) * np.exp(-0.5 * xa * xa - _LOG_SQRT_2PI - lg)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = h / dlg
            new = xa - step
            l_a, h_a = lo[active], hi[active]
            # A Newton step below tolerance has converged even if rounding puts it on the bracket.
            conv = np.abs(step) <= tol * (1.0 + np.abs(xa))
            bad = ~conv & (~np.isfinite(new) | (new <= l_a) | (new >= h_a))
            new = np.where(bad, 0.5 * (l_a + h_a), new)
            xx[active] = new
            done = conv | (h_a - l_a <= tol * (1.0 + np.abs(new)))
            active = active[~done]
            if active.size == 0:
                break
        x[idx] = xx
    return x


class Beckmann(MicrofacetModel):
    """Beckmann NDF with Gaussian slopes ``N(mean_slope, slope_cov)`` (LEAN/LEADR).

    Parameters
    ----------
    mean_slope : array_like, shape (..., 2)
        Mean slope ``E[s]``, ``s = (-mx/mz, -my/mz)``.
    slope_cov : array_like, shape (..., 2, 2)
        Slope covariance, symmetric positive definite. Batch dimensions of both parameters
        broadcast against each other and against the directions passed to the methods.
    """

    #: Gauss-Legendre nodes per axis in :meth:`albedo` (error ~1e-5 for narrow non-centred lobes).
    albedo_nodes: int = 128

    def __init__(self, mean_slope, slope_cov):
        mu = as_float_array(mean_slope, "mean_slope", ndim_min=1, last_dim=2)
        cov = as_float_array(slope_cov, "slope_cov", ndim_min=2)
        if cov.shape[-2:] != (2, 2):
            raise PrefilterError(f"slope_cov: expected shape (..., 2, 2), got shape {cov.shape}")
        sxx, syy, sxy, syx = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1], cov[..., 1, 0]
        scale = np.maximum(np.abs(sxx), np.abs(syy))
        if np.any(np.abs(sxy - syx) > 1e-9 * scale + 1e-300):
            raise PrefilterError(
                f"slope_cov: expected a symmetric matrix, got off-diagonals {sxy} and {syx}"
            )
        sxy = 0.5 * (sxy + syx)
        det = sxx * syy - sxy * sxy
        # A symmetric 2x2 matrix is positive definite iff its trace and determinant are.
        if np.any(sxx <= 0.0) or np.any(syy <= 0.0) or np.any(det <= 1e-14 * scale * scale):
            eig = np.linalg.eigvalsh(np.stack([np.stack([sxx, sxy], -1),
                                               np.stack([sxy, syy], -1)], -2))
            raise PrefilterError(
                "slope_cov: expected a positive definite covariance (eigenvalues > 0), got "
                f"eigenvalues {np.array2string(eig.reshape(-1, 2)[:3], precision=4)}"
            )
        try:
            np.broadcast_shapes(mu.shape[:-1], cov.shape[:-2])
        except ValueError as exc:
            raise PrefilterError(
                f"mean_slope {mu.shape} and slope_cov {cov.shape}: batch shapes do not broadcast"
            ) from exc
        self.mean_slope = mu
        self.slope_cov = np.stack([np.stack([sxx, sxy], -1), np.stack([sxy, syy], -1)], -2)
        self._sxx, self._syy, self._sxy, self._det = sxx, syy, sxy, det

    @classmethod
    def isotropic(cls, alpha) -> "Beckmann":
        """Centred isotropic Beckmann of roughness ``alpha (...)``: slope variance ``alpha^2 / 2``.

        ``D(m) = exp(-tan^2(theta) / alpha^2) / (pi alpha^2 cos^4(theta))`` (Walter et al. 2007
        eq. 25).
        """
        alpha = as_roughness(alpha, "alpha")
        var = 0.5 * alpha**2
        eye = np.eye(2)
        return cls(np.zeros(alpha.shape + (2,)), var[..., None, None] * eye)

    @classmethod
    def anisotropic(cls, alpha_x, alpha_y, mean_slope=(0.0, 0.0)) -> "Beckmann":
        """Axis-aligned Beckmann with roughness ``alpha_x, alpha_y`` (variances ``alpha^2 / 2``)."""
        ax = as_roughness(alpha_x, "alpha_x")
        ay = as_roughness(alpha_y, "alpha_y")
        ax, ay = np.broadcast_arrays(ax, ay)
        cov = np.zeros(ax.shape + (2, 2))
        cov[..., 0, 0] = 0.5 * ax**2
        cov[..., 1, 1] = 0.5 * ay**2
        return cls(mean_slope, cov)

    def __repr__(self) -> str:
        return (f"Beckmann(mean_slope={self.mean_slope.tolist()}, "
                f"slope_cov={self.slope_cov.tolist()})")

    def _scalar_params(self) -> bool:
        return self.mean_slope.ndim == 1 and self.slope_cov.ndim == 2

    def _with_trailing_axis(self) -> "Beckmann":
        return Beckmann(self.mean_slope[..., None, :], self.slope_cov[..., None, :, :])

    def P22(self, s) -> np.ndarray:
        """Slope density ``N(s; mu, Sigma)`` for slopes ``s (..., 2)`` (:func:`slope_pdf`)."""
        s = np.asarray(s, dtype=np.float64)
        return slope_pdf(s[..., 0] - self.mean_slope[..., 0], s[..., 1] - self.mean_slope[..., 1],
                         self._sxx, self._syy, self._sxy)

    def D(self, m) -> np.ndarray:
        """NDF ``P22(s(m)) / mz^4`` (LEADR supplemental 3.1), ``(...,)``; 0 for ``mz <= 0``."""
        m = as_directions(m, "m")
        mz = m[..., 2]
        # Below 1e-60 the slope density has underflowed long before mz^4 does.
        up = mz > 1e-60
        mzs = np.where(up, mz, 1.0)
        s = -m[..., :2] / mzs[..., None]
        return np.where(up, self.P22(s) / mzs**4, 0.0)

    def _slope_stats(self, w):
        """``d = w_z - mu.w_xy`` and ``sigma = sqrt(w_xy^T Sigma w_xy)`` for ``w (..., 3)``."""
        wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
        d = wz - self.mean_slope[..., 0] * wx - self.mean_slope[..., 1] * wy
        var = self._sxx * wx * wx + 2.0 * self._sxy * wx * wy + self._syy * wy * wy
        return d, np.sqrt(np.maximum(var, 0.0))

    def _a(self, w):
        """``a = (cot(theta) - mu_phi) / (sqrt(2) sigma_phi)`` (equations.md 1), +-inf if
        sigma = 0."""
        d, sigma = self._slope_stats(w)
        pos = sigma > 0.0
        a = d / (_SQRT2 * np.where(pos, sigma, 1.0))
        return np.where(pos, a, np.where(d > 0.0, np.inf, -np.inf)), d, sigma

    def smith_lambda(self, w) -> np.ndarray:
        """Exact Smith ``Lambda(w)`` for Gaussian slopes, ``(...,)`` (:func:`beckmann_lambda`).

        Uses the sign of ``w_z``; ``+inf`` where ``w`` is at or below the mean surface.
        """
        w = as_directions(w, "w")
        a, _, _ = self._a(w)
        return beckmann_lambda(a)

    def mean_projected_area(self, w) -> np.ndarray:
        """``A(w) = w_z - mu . w_xy = (n_bar.w) / (n_bar.z)`` for ``w (..., 3)``."""
        w = as_directions(w, "w")
        return self._slope_stats(w)[0]

    def projected_area(self, w) -> np.ndarray:
        """``integral max(0, w.m) D(m) dm = E[max(0, d - X)]``, ``X ~ N(0, sigma^2)``.

        Closed form ``d Phi(t) + sigma phi(t)``, ``t = d / sigma``; positive even below the mean
        surface, where it is written ``sigma phi(t) (1 - |t| R(|t|))`` (Mills' ratio ``R``).
        """
        w = as_directions(w, "w")
        d, sigma = self._slope_stats(w)
        pos = sigma > 0.0
        t = d / np.where(pos, sigma, 1.0)
        phi = np.exp(-0.5 * t * t - _LOG_SQRT_2PI)
        above = d * special.ndtr(t) + sigma * phi
        tn = np.abs(t)
        below = sigma * phi * np.maximum(
            0.0, 1.0 - tn * np.sqrt(np.pi / 2) * special.erfcx(tn / _SQRT2))
        area = np.where(t >= 0.0, above, below)
        return np.where(pos, area, np.maximum(d, 0.0))

    def sample_vndf(self, wo, u) -> np.ndarray:
        """Exact visible normals ``m (..., 3)`` for views ``wo (..., 3)`` and uniforms
        ``u (..., 2)``.

        In slope space the visible density is ``max(0, wo_z - s.wo_xy) P22(s)``. With
        ``s = mu + L z`` (``Sigma = L L^T``) the ramp depends only on ``x = e.z``,
        ``e = L^T wo_xy / |L^T wo_xy|``: ``x`` has density ``~ (a - x) phi(x)`` on ``x < a``
        (``a = d / sigma``, inverted numerically to 1e-12) and the orthogonal coordinate is a
        standard normal. Density :meth:`pdf_vndf`.
        """
        wo = as_directions(wo, "wo")
        u = as_uniform(u, "u", last_dim=2)
        a, ex, ey = self._view_whitening(wo)
        shape = np.broadcast_shapes(a.shape, u.shape[:-1])
        x = _sample_ramp(np.broadcast_to(a, shape), np.broadcast_to(u[..., 0], shape))
        x = x.reshape(shape)
        y = special.ndtri(np.clip(u[..., 1], 2.0**-60, 1.0 - 2.0**-53))
        return self._normal_from_whitened(x, y, ex, ey)

    def _view_whitening(self, wo):
        """Ramp parameter ``a = d / sigma`` and the unit vector ``e = L^T wo_xy / sigma``."""
        d, sigma = self._slope_stats(wo)
        l11, l21, l22 = self._cholesky()
        ex = l11 * wo[..., 0] + l21 * wo[..., 1]
        ey = l22 * wo[..., 1]
        pos = sigma > 1e-300 * (1.0 + np.abs(d))
        ex = np.where(pos, ex / np.where(pos, sigma, 1.0), 1.0)
        ey = np.where(pos, ey / np.where(pos, sigma, 1.0), 0.0)
        a = np.where(pos, d / np.where(pos, sigma, 1.0), np.inf)
        return a, ex, ey

    def _cholesky(self):
        """Entries of the lower Cholesky factor ``L = [[l11, 0], [l21, l22]]`` of ``Sigma``."""
        l11 = np.sqrt(self._sxx)
        return l11, self._sxy / l11, np.sqrt(self._det / self._sxx)

    def _slope_from_whitened(self, x, y, ex, ey):
        """``s = mu + L z`` with ``z = x e + y e_perp`` (whitened coordinates along the view)."""
        l11, l21, l22 = self._cholesky()
        zx = x * ex - y * ey
        zy = x * ey + y * ex
        return self.mean_slope[..., 0] + l11 * zx, self.mean_slope[..., 1] + l21 * zx + l22 * zy

    def _normal_from_whitened(self, x, y, ex, ey):
        sx, sy = self._slope_from_whitened(x, y, ex, ey)
        m = np.stack(np.broadcast_arrays(-sx, -sy, np.ones_like(sx)), -1)
        return m / np.linalg.norm(m, axis=-1, keepdims=True)

    def albedo(self, wo) -> np.ndarray:
        """Directional albedo ``integral eval(wo, wi) dwi = E_vndf[G2 / G1]`` for ``wo (..., 3)``.

        Deterministic quadrature in the whitened slope coordinates of :meth:`sample_vndf`. The
        reflected direction is above the horizon iff the slope lies in the disk
        ``|s + wo_xy / wo_z| <= 1 / wo_z``; with a non-zero mean slope ``G2`` jumps to 0 there, so
        the quadrature is restricted to that disk (an ellipse in whitened coordinates), which
        keeps Gauss-Legendre convergence spectral instead of O(1/n).
        """
        wo = as_directions(wo, "wo")
        k = self.albedo_nodes
        xg, wg = np.polynomial.legendre.leggauss(k)
        # u = (1 - cos(pi t)) / 2 packs nodes towards the ends of the CDF ranges, where narrow
        # lobes cut off a small tail (reflection below the horizon or the mean surface).
        tg, wg = ((1.0 - np.cos(np.pi * (xg + 1) / 2)) / 2,
                  wg * np.pi / 4 * np.sin(np.pi * (xg + 1) / 2))
        seen = wo[..., 2] > 0.0
        wo = np.where(seen[..., None], wo, np.array([0.0, 0.0, 1.0]))
        lam_o = self.smith_lambda(wo)
        seen = seen & np.isfinite(lam_o)
        a, ex, ey = self._view_whitening(wo)
        l11, l21, l22 = self._cholesky()
        # Disk |b + x p + y q| <= r in whitened coordinates: p = L e, q = L e_perp.
        wz = wo[..., 2]
        bx = self.mean_slope[..., 0] + wo[..., 0] / wz
        by = self.mean_slope[..., 1] + wo[..., 1] / wz
        r2 = 1.0 / wz**2
        px, py = l11 * ex, l21 * ex + l22 * ey
        qx, qy = -l11 * ey, -l21 * ey + l22 * ex
        qq = qx * qx + qy * qy
        # Chord in y exists where the distance of b + x p from the line along q is <= r:
        # |cross(q, b + x p)|^2 <= r^2 |q|^2, a quadratic inequality in x.
        cb = qx * by - qy * bx
        cp = qx * py - qy * px
        half = np.sqrt(r2 * qq)
        x1 = (-half - cb) / cp
        x2 = (half - cb) / cp
        x_lo, x_hi = np.minimum(x1, x2), np.maximum(x1, x2)
        x_top = np.minimum(x_hi, a)
        f_lo = _ramp_cdf(x_lo, a)
        f_hi = _ramp_cdf(x_top, a)
        mass_x = np.maximum(f_hi - f_lo, 0.0)
        u1 = f_lo[..., None] + mass_x[..., None] * tg
        shape = np.broadcast_shapes(np.shape(a) + (k,), u1.shape)
        x = _sample_ramp(np.broadcast_to(a[..., None], shape), np.broadcast_to(u1, shape))
        x = np.minimum(x.reshape(shape), x_top[..., None])
        # Chord in y for each x node: |b + x p + y q|^2 = r^2.
        cx = bx[..., None] + x * px[..., None]
        cy = by[..., None] + x * py[..., None]
        qd = (qx[..., None] * cx + qy[..., None] * cy) / qq[..., None]
        disc = np.maximum(qd * qd - (cx * cx + cy * cy - r2[..., None]) / qq[..., None], 0.0)
        y1, y2 = -qd - np.sqrt(disc), -qd + np.sqrt(disc)
        # G2 also vanishes where wi is below the mean surface: along s = s0 + y q that is
        # F(y) = 2 (wo_z - s.v)(1 + s.mu) - A (1 + |s|^2) < 0 (from wi.n_bar < 0), a quadratic.
        ex_, ey_ = ex[..., None], ey[..., None]
        trail = self._with_trailing_axis()
        s0x, s0y = trail._slope_from_whitened(x, 0.0, ex_, ey_)
        sqx, sqy = trail._slope_from_whitened(0.0, 1.0, ex_, ey_)
        mux, muy = self.mean_slope[..., 0, None], self.mean_slope[..., 1, None]
        sqx, sqy = sqx - mux, sqy - muy
        vx, vy = wo[..., 0, None], wo[..., 1, None]
        area = self.mean_projected_area(wo)[..., None]
        qv, qm = sqx * vx + sqy * vy, sqx * mux + sqy * muy
        ramp0, lift0 = wz[..., None] - (s0x * vx + s0y * vy), 1.0 + s0x * mux + s0y * muy
        fa = -2.0 * qv * qm - area * (sqx * sqx + sqy * sqy)
        fb = 2.0 * (ramp0 * qm - qv * lift0) - 2.0 * area * (s0x * sqx + s0y * sqy)
        fc = 2.0 * ramp0 * lift0 - area * (1.0 + s0x * s0x + s0y * s0y)
        fdisc = fb * fb - 4.0 * fa * fc
        sq = np.sqrt(np.maximum(fdisc, 0.0))
        qq_ = -0.5 * (fb + np.where(fb >= 0.0, sq, -sq))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ra, rb = qq_ / fa, fc / qq_
        r_lo = np.where(np.isfinite(ra) & np.isfinite(rb), np.minimum(ra, rb), -np.inf)
        r_hi = np.where(np.isfinite(ra) & np.isfinite(rb), np.maximum(ra, rb), np.inf)
        inside = fa < 0.0  # F >= 0 between the roots; otherwise outside them
        real = fdisc >= 0.0
        # Up to two intervals [l1, h1], [l2, h2] inside the horizon chord [y1, y2].
        l1 = np.where(inside, np.maximum(y1, r_lo), y1)
        h1 = np.where(inside, np.minimum(y2, r_hi), np.where(real, np.minimum(y2, r_lo), y2))
        l2 = np.where(inside | ~real, y2, np.maximum(y1, r_hi))
        h2 = y2
        h1 = np.where(inside & ~real, l1, h1)
        lo1 = 1.0 + np.where(seen, lam_o, 0.0)
        model = Beckmann(self.mean_slope[..., None, None, :], self.slope_cov[..., None, None, :, :])
        wo_b = wo[..., None, None, :]
        inner = 0.0
        for lo_y, hi_y in ((l1, h1), (l2, h2)):
            hi_y = np.maximum(hi_y, lo_y)
            g_lo, g_hi = special.ndtr(lo_y), special.ndtr(hi_y)
            mass_y = g_hi - g_lo
            u2 = g_lo[..., None] + mass_y[..., None] * tg
            y = special.ndtri(np.clip(u2, 2.0**-60, 1.0 - 2.0**-53))
            y = np.clip(y, lo_y[..., None], hi_y[..., None])
            m = model._normal_from_whitened(x[..., None], y, ex[..., None, None],
                                            ey[..., None, None])
            wi = 2.0 * np.sum(wo_b * m, axis=-1, keepdims=True) * m - wo_b
            wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
            lam_i = model.smith_lambda(wi)
            ratio = 1.0 / (1.0 + lam_i / lo1[..., None, None])
            ratio = np.where(wi[..., 2] > 0.0, ratio, 0.0)
            inner = inner + np.sum(ratio * wg, axis=-1) * mass_y
        total = np.sum(inner * wg, axis=-1) * mass_x
        return np.where(seen, total, 0.0)
