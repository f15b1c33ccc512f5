"""Direct position-normal NDF of a normal map over a Gaussian footprint (Yan et al. 2016).

Conventions (used by the whole ``prefilter.glints`` package):

* A normal map is ``(H, W, 3)`` unit tangent-space normals with ``n_z > 0``; texel ``[row, col]``
  is centred at texture position ``u = (x, y) = (col + 0.5, row + 0.5)`` in texel units (as in
  ``prefilter.texture.procedural``). The map is treated as
  periodic (a tile), so footprints near or larger than the map wrap around.
* Projected normals ``s = (n_x, n_y)`` live in the unit disk. ``D_p(s)`` is a density w.r.t. ``s``:
  ``integral D_p(s) ds = 1``.
* On the hemisphere ``m = (s, sqrt(1 - |s|^2))`` the solid angle is ``dw = ds / m_z``. ``D_p(s) ds``
  is the fraction of *macro-surface* area whose normal falls in ``ds`` and the microfacet NDF obeys
  ``D(m) m_z dw = fraction of macro area``, so ``D(m) = D_p(s(m))`` with no extra factor, and
  ``integral D(m) m_z dm = 1`` (tested by quadrature on the hemisphere).

Each texel ``i`` is a 4D element ``g_i(u) N(s; n_i + J_i (u - u_i), sigma_r^2)`` with
``g_i(u) = exp(-|u - u_i|^2 / (2 sigma_h^2))``, ``sigma_h`` a FWHM of one texel, ``J_i`` the central
finite-difference Jacobian ``ds/du``. Against the footprint ``G_p(u) = exp(-|u - u_p|^2 / (2
sigma_p^2))`` the ``u`` integral is closed form: element ``i`` contributes a 2D Gaussian in
``s`` with

    weight  w_i = exp(-|u_p - u_i|^2 / (2 (sigma_p^2 + sigma_h^2)))
    mean    n_i + J_i mu_i,   mu_i = (u_p - u_i) sigma_h^2 / (sigma_p^2 + sigma_h^2)
    cov     sigma_r^2 I + sigma^2 J_i J_i^T,
            sigma^2 = sigma_p^2 sigma_h^2 / (sigma_p^2 + sigma_h^2)

and ``D_p(s) = sum_i w_i N_i(s) / sum_i w_i`` (normalised exactly). Elements with ``|u_p - u_i|``
beyond ``TRUNCATION`` standard deviations (per axis) are skipped: the texel grid is the spatial
acceleration structure, so the cost is proportional to the texels under the footprint.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from prefilter.jit import kernel_array, njit_inline, njit_parallel, njit_serial, prange
from prefilter.validation import (
    as_float_array,
    as_positive_int,
    as_upper_directions,
    broadcast_batch,
)
from prefilter.errors import PrefilterError

SIGMA_H = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))  # FWHM of one texel (Yan et al. 2016)
TRUNCATION = 4.0  # footprint Gaussians are cut at 4 sigma per axis (mass lost < 1.3e-4)
DEFAULT_ROUGHNESS = 0.005  # intrinsic roughness sigma_r (Yan et al. 2016)
#: Version of what :func:`pndf_image` computes (3: the rank-one part by 3- / 5-point
#: Gauss-Hermite up to :data:`GH3_MAX` / :data:`GH5_MAX` and line nodes at a step of the integrand's
#: std, :func:`node_count`; 2: line nodes cut at :func:`node_reach`); bakes key their checkpoints
#: and cache files on it (:func:`prefilter.glints.bake.code_versions`).
IMAGE_VERSION = 3
#: Largest ``kappa / siso`` of the 3-point and 5-point Gauss-Hermite rules for an element's
#: rank-one part (probabilists' nodes; largest error over the element's peak, point values:
#: 3-point 8e-5 at 0.3, 1.5e-3 at 0.5, 8.9e-3 at 0.7; 5-point 1.9e-5 at 0.5, 3.5e-4 at 0.7,
#: 5.4e-3 at 1.0); longer elements use :func:`line_nodes`.
GH3_MAX = 0.3
GH5_MAX = 0.6
#: 5-point Gauss-Hermite nodes and weights of the standard normal
GH5_T = (1.3556261799742657, 2.8569700138728056)
GH5_W = (0.5333333333333333, 0.2220759220056127, 0.011257411327720667)


# ---------------------------------------------------------------------------------------------
# validation


def as_normal_map(normal_map, name: str = "normal_map") -> np.ndarray:
    """A validated ``(H, W, 3)`` float64 normal map of unit normals with ``n_z > 0``."""
    dtype = getattr(normal_map, "dtype", None)
    if dtype is not None and (np.issubdtype(dtype, np.integer) or dtype == np.bool_):
        raise PrefilterError(
            f"{name}: expected unit normals (floats), got an integer ({dtype}) array: decode "
            "8/16-bit normal-map colours first with prefilter.texture.decode_normals(rgb, "
            "convention)")
    a = as_float_array(normal_map, name, ndim_min=3, last_dim=3)
    if a.ndim != 3 or a.shape[0] < 2 or a.shape[1] < 2:
        raise PrefilterError(f"{name}: expected shape (H, W, 3) with H, W >= 2, got {a.shape}")
    return np.ascontiguousarray(as_upper_directions(a, name, tol=1e-2))


def as_intrinsic_roughness(sigma_r, name: str = "intrinsic_roughness") -> float:
    """A validated intrinsic roughness ``sigma_r`` (std of each element in ``s``)."""
    try:
        v = float(sigma_r)
    except (TypeError, ValueError) as exc:
        raise PrefilterError(f"{name}: expected a number, got {sigma_r!r}") from exc
    if not (1e-4 <= v <= 0.5):
        raise PrefilterError(f"{name}: expected intrinsic roughness in [1e-4, 0.5], got {v!r}")
    return v


def as_sigma_p(sigma_p, name: str = "sigma_p") -> np.ndarray:
    """Validated footprint stds ``(...)`` in texels."""
    a = as_float_array(sigma_p, name)
    if np.any(a < 0.0) or np.any(a > 1e6):
        raise PrefilterError(f"{name}: expected footprint std in texels in [0, 1e6], got {a}")
    return a


def as_footprints(center, sigma_p, **batch) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Validated footprint centres ``(..., 2)`` and stds ``(...)`` (texels, ``>= 0``) and the
    batch shape they broadcast to together with the named shapes ``batch``
    (:func:`prefilter.validation.broadcast_batch`)."""
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_float_array(sigma_p, "sigma_p")
    if np.any(sp < 0):
        raise PrefilterError(f"sigma_p: expected footprint stds >= 0, got min {sp.min()}")
    return c, sp, broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape, **batch)


def as_support(support, name: str = "support") -> float:
    """A validated half-width of the NDF images' square in ``s``."""
    try:
        v = float(support)
    except (TypeError, ValueError) as exc:
        raise PrefilterError(f"{name}: expected a number, got {support!r}") from exc
    if not (0.0 < v <= 1.0):
        raise PrefilterError(f"{name}: expected a half-width of the s-square in (0, 1], got {v!r}")
    return v


def as_ndf_truncation(ndf_truncation, name: str = "ndf_truncation") -> float:
    """A validated cut of a Gaussian (elements in ``s``, footprint weights), in stds, in [3, 8]."""
    try:
        v = float(ndf_truncation)
    except (TypeError, ValueError) as exc:
        raise PrefilterError(f"{name}: expected a number, got {ndf_truncation!r}") from exc
    if not (3.0 <= v <= 8.0):
        raise PrefilterError(f"{name}: expected a number of standard deviations in [3, 8], "
                             f"got {v!r}")
    return v


# ---------------------------------------------------------------------------------------------
# elements


def map_digest(normal_map: np.ndarray) -> str:
    """SHA-1 (hex) of a validated normal map's float64 values: what a bake records
    (``map_sha1``), what :func:`prefilter.glints.surface.surface` checks and what the render and
    Wang-tile caches are keyed by."""
    return hashlib.sha1(np.ascontiguousarray(normal_map, dtype=np.float64).tobytes()).hexdigest()


def elements(normal_map) -> tuple[np.ndarray, np.ndarray]:
    """Per-texel element centres and Jacobians of a normal map (Yan et al. 2016, sec. 4).

    Parameters
    ----------
    normal_map : (H, W, 3) unit normals, periodic.

    Returns
    -------
    s : (H, W, 2) projected normals ``n_i``.
    J : (H, W, 2, 2) central-difference Jacobians, ``J[..., a, b] = d s_a / d u_b`` with
        ``u = (x, y)``, ``x`` along columns.
    """
    n = as_normal_map(normal_map)
    s = np.ascontiguousarray(n[..., :2])
    J = np.empty(s.shape[:2] + (2, 2))
    J[..., :, 0] = 0.5 * (np.roll(s, -1, axis=1) - np.roll(s, 1, axis=1))
    J[..., :, 1] = 0.5 * (np.roll(s, -1, axis=0) - np.roll(s, 1, axis=0))
    return s, J


def pixel_edges(resolution: int, support: float) -> np.ndarray:
    """Edges ``(resolution + 1,)`` of the NDF-image pixels along one axis of
    ``[-support, support]``."""
    return np.linspace(-support, support, resolution + 1)


def pixel_centers(resolution: int, support: float) -> np.ndarray:
    e = pixel_edges(resolution, support)
    return 0.5 * (e[1:] + e[:-1])


# ---------------------------------------------------------------------------------------------
# Numba kernels (the public ones are shared by the other glints kernels)


_PHI_LO, _PHI_N = -6.0, 8192
_PHI_STEP = -2.0 * _PHI_LO / _PHI_N
# Tabulated standard normal CDF: linear interpolation error <= step^2 / 8 * max|phi'| < 3e-8, and
# erfc dominated the splat cost.
_PHI_TABLE = np.array([0.5 * math.erfc(-(_PHI_LO + k * _PHI_STEP) / math.sqrt(2.0))
                       for k in range(_PHI_N + 1)])


@njit_serial
def normal_cdf(z):  # pragma: no cover - compiled
    """Standard normal CDF ``Phi(z)``, interpolated in a table (the splats' pixel masses)."""
    t = (z - _PHI_LO) / _PHI_STEP
    if t <= 0.0:
        return 0.0
    if t >= _PHI_N:
        return 1.0
    k = int(t)
    f = t - k
    return _PHI_TABLE[k] + f * (_PHI_TABLE[k + 1] - _PHI_TABLE[k])


@njit_serial
def texel_window(c, rad):  # pragma: no cover - compiled
    """First and last texel index along one axis whose centre ``index + 0.5`` lies within
    ``c +- rad``."""
    return int(math.ceil(c - rad - 0.5)), int(math.floor(c + rad - 0.5))


@njit_serial
def footprint_window(cx, cy, sp, sh2, trunc, H, W, lim2):
    """Texel window, mean-shift factor ``f``, element variance ``var`` and whether the footprint
    covers so many tiles that it is the sigma_p -> inf limit (``wide``: every texel once, equal
    weights, no mean shift, ``var = sigma_h^2``). The limit is exact to ``exp(-2 pi^2 tot2 / L^2)``
    (Poisson summation of the periodic weights) and ``(sigma_h^2 / tot2)`` in the shape; it
    bounds the cost by the texel count (a footprint of 1e4 texels visited 6e9 copies)."""
    sp2 = sp * sp
    tot2 = sp2 + sh2
    if tot2 >= lim2:
        return 0, W - 1, 0, H - 1, 0.0, sh2, tot2, True
    rad = trunc * math.sqrt(tot2)
    x0, x1 = texel_window(cx, rad)
    y0, y1 = texel_window(cy, rad)
    return x0, x1, y0, y1, sh2 / tot2, sp2 * sh2 / tot2, tot2, False


@njit_inline
def element_covariance(j00, j01, j10, j11, var, sr2):  # pragma: no cover - compiled
    """Covariance ``(a, b, d)`` = ``[[a, b], [b, d]] = sr2 I + var J J^T`` of an element's
    Gaussian in ``s`` (Yan et al. 2016), ``J = [[j00, j01], [j10, j11]]`` the texel's slope
    Jacobian, ``var`` the footprint-conditioned positional variance, ``sr2`` the intrinsic
    roughness squared (0: the positional part alone)."""
    return (sr2 + var * (j00 * j00 + j01 * j01), var * (j00 * j10 + j01 * j11),
            sr2 + var * (j10 * j10 + j11 * j11))


@njit_inline
def element_moments(s_el, J, r, c, dx, dy, f, var):  # pragma: no cover - compiled
    """Mean slope ``(mx, my)`` and positional covariance ``(a, b, d)`` (without the intrinsic
    roughness) of texel ``(r, c)``'s element seen from a footprint offset ``(dx, dy)``: the
    4D Gaussian's slope marginal conditioned on the footprint (Yan et al. 2016)."""
    return element_gaussian(s_el, J, r, c, dx, dy, f, var, 0.0)


@njit_inline
def element_gaussian(s_el, J, r, c, dx, dy, f, var, sr2):  # pragma: no cover - compiled
    """:func:`element_moments` with the intrinsic roughness ``sr2 = sigma_r^2`` on the
    covariance's diagonal: the element's Gaussian in ``s`` (Yan et al. 2016)."""
    j00, j01, j10, j11 = J[r, c, 0, 0], J[r, c, 0, 1], J[r, c, 1, 0], J[r, c, 1, 1]
    mx = s_el[r, c, 0] + f * (j00 * dx + j01 * dy)
    my = s_el[r, c, 1] + f * (j10 * dx + j11 * dy)
    a, b, d = element_covariance(j00, j01, j10, j11, var, sr2)
    return mx, my, a, b, d


@njit_inline
def element_density(ex, ey, a, b, d, cut):  # pragma: no cover - compiled
    """Density ``N((ex, ey); 0, [[a, b], [b, d]])`` of an element's Gaussian at the offset
    ``(ex, ey)`` from its mean, 0 where the squared Mahalanobis distance is ``>= cut``."""
    det = a * d - b * b
    quad = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
    if quad >= cut:
        return 0.0
    return math.exp(-0.5 * quad) / (2.0 * math.pi * math.sqrt(det))


@njit_inline
def element_draw(mx, my, a, b, d, u1, u2):  # pragma: no cover - compiled
    """A draw from ``N((mx, my), [[a, b], [b, d]])`` for the uniforms ``u1, u2``: the Cholesky
    factor applied to a Box-Muller pair."""
    l11 = math.sqrt(a)
    l21 = b / l11
    l22 = math.sqrt(max(d - l21 * l21, 0.0))
    rr = math.sqrt(-2.0 * math.log(1.0 - u1))
    z1 = rr * math.cos(2.0 * math.pi * u2)
    z2 = rr * math.sin(2.0 * math.pi * u2)
    return mx + l11 * z1, my + l21 * z1 + l22 * z2


@njit_inline
def footprint_weights(cx, cy, x0, x1, y0, y1, tot2, out):  # pragma: no cover - compiled
    """Gaussian footprint weights ``exp(-|c - u_i|^2 / (2 tot2))`` of the window's texels,
    row-major into ``out (>= n_texels,)``; returns their sum (Yan et al. 2016)."""
    wsum = 0.0
    n = 0
    for y in range(y0, y1 + 1):
        dy = cy - (y + 0.5)
        for x in range(x0, x1 + 1):
            dx = cx - (x + 0.5)
            out[n] = math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
            wsum += out[n]
            n += 1
    return wsum


@njit_inline
def choose_texel(wb, wsum, x0, x1, y0, y1, u):  # pragma: no cover - compiled
    """Texel ``(x, y)`` of the window drawn with probability ``wb / wsum`` (weights of
    :func:`footprint_weights`) by the uniform ``u``; the last texel if rounding runs out."""
    t = u * wsum
    run = 0.0
    n = 0
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            run += wb[n]
            n += 1
            if t < run:
                return x, y
    return x1, y1


@njit_inline
def element_split(a, b, d, sr):  # pragma: no cover - compiled
    """Exact split of an element's slope covariance ``sr^2 I + [[a, b], [b, d]]`` into an
    isotropic part ``siso^2 I`` and a rank-one part ``kappa^2 v v^T`` (eigenvalues ``nu1 >= nu2``
    of ``[[a, b], [b, d]]``: ``siso^2 = sr^2 + nu2``, ``kappa^2 = nu1 - nu2``), so the isotropic
    part splats by separable erf masses and the rest is a 1D quadrature along ``v``
    (:func:`principal_axis`; 3-point Gauss-Hermite while ``kappa <= 0.7 siso``, else
    :func:`line_nodes`).

    Scalars in, ``(nu1, siso, kappa)`` out; ``sqrt(nu1 + sr^2)`` is the element's largest std
    (its reach, which culls most elements before ``v`` is needed)."""
    half = 0.5 * (a + d)
    dif = math.sqrt(0.25 * (a - d) * (a - d) + b * b)
    nu1 = half + dif
    nu2 = max(half - dif, 0.0)
    return nu1, math.sqrt(sr * sr + nu2), math.sqrt(max(nu1 - nu2, 0.0))


@njit_inline
def principal_axis(a, b, d, nu1):  # pragma: no cover - compiled
    """Unit eigenvector ``(vx, vy)`` of ``[[a, b], [b, d]]`` for its largest eigenvalue ``nu1``
    (:func:`element_split`); ``(1, 0)`` when the matrix is isotropic."""
    # from the row of (A - nu1 I) with the larger diagonal gap (no cancellation)
    if a >= d:
        vx, vy = nu1 - d, b
    else:
        vx, vy = b, nu1 - a
    vn = math.sqrt(vx * vx + vy * vy)
    if vn == 0.0:
        return 1.0, 0.0
    return vx / vn, vy / vn


@njit_inline
def node_count(kappa, siso, trunc):  # pragma: no cover - compiled
    """Line nodes over ``[-trunc, trunc]`` (in stds of the rank-one part): at least 9, the step
    at most 1.5 stds of the trapezoid rule's integrand along the line, a Gaussian in ``t`` of std
    ``1 / sqrt(1 + kappa^2 / siso^2)`` (aliasing ~ 2 exp(-2 pi^2 / 1.5^2) ~ 3e-4 of the peak;
    the step 1.5 ``siso / kappa`` of the long-element limit is 2.1 of those stds at
    ``kappa = siso``: 2.5e-2)."""
    q = kappa / siso
    return max(9, int(math.ceil(2.0 * trunc * math.sqrt(1.0 + q * q) / 1.5)) + 1)


#: Line-node counts tabulated by :data:`LINE_NORMS` (more nodes: the normaliser is summed).
_NORMS_MAX = 1024


def _line_norms(trunc: float, n_max: int) -> np.ndarray:
    """``(n_max,)``: the normaliser ``sum_k exp(-t_k^2 / 2)`` of ``n`` line nodes ``t_k = -trunc
    + 2 trunc k / (n - 1)`` for each ``n >= 2`` (entries 0 and 1 unused)."""
    out = np.zeros(n_max)
    for n in range(2, n_max):
        t = -trunc + 2.0 * trunc * np.arange(n) / (n - 1)
        out[n] = float(np.exp(-0.5 * t * t).sum())
    return out


#: :func:`line_nodes`' normalisers at ``TRUNCATION`` (no sum of ``n`` exponentials an element).
LINE_NORMS = _line_norms(TRUNCATION, _NORMS_MAX)


@njit_inline
def line_nodes(kappa, siso, trunc):  # pragma: no cover - compiled
    """Node count ``n`` (:func:`node_count`) and weight normaliser ``norm`` of the rank-one
    part's quadrature: nodes ``t_k = kappa (-trunc + 2 trunc k / (n - 1))``, weights
    ``exp(-t_k^2 / (2 kappa^2)) / norm`` (used when ``kappa > GH5_MAX siso``); ``norm`` from
    :data:`LINE_NORMS` at ``TRUNCATION``."""
    n = node_count(kappa, siso, trunc)
    if trunc == TRUNCATION and n < _NORMS_MAX:
        return n, LINE_NORMS[n]
    norm = 0.0
    for k in range(n):
        tk = -trunc + 2.0 * trunc * k / (n - 1)
        norm += math.exp(-0.5 * tk * tk)
    return n, norm


@njit_inline
def element_nodes(kappa, siso, trunc):  # pragma: no cover - compiled
    """Node count ``n`` and normaliser ``norm`` of an element's quadrature along its rank-one
    axis (:func:`element_split`): 1 (isotropic, ``kappa < 1e-3 siso``), 3 or 5 (Gauss-Hermite
    while ``kappa <= GH3_MAX`` / ``GH5_MAX siso``), else :func:`line_nodes`' ``n >= 9``. Node
    ``q < n``: :func:`element_node`. The one rule of the splats, pixel values and rectangle
    masses of elements (:func:`splat_element`, ``wang_ndf``, ``wang_range``)."""
    if kappa < 1e-3 * siso:
        return 1, 1.0
    if kappa <= GH3_MAX * siso:
        return 3, 1.0
    if kappa <= GH5_MAX * siso:
        return 5, 1.0
    return line_nodes(kappa, siso, trunc)


@njit_inline
def element_node(kappa, trunc, n, norm, q):  # pragma: no cover - compiled
    """Node ``q`` of :func:`element_nodes`' rule ``(n, norm)``: its offset ``t`` along the
    principal axis (absolute), weight ``num / den`` (as ``w * num / den``, the arithmetic of
    each rule's own weights) and the stds its isotropic part is cut at. Gauss-Hermite: 3 points
    (exact mean, variance and kurtosis) or 5, centre first then ``+`` / ``-`` pairs; line:
    ``t = kappa t_q``, weight ``exp(-t_q^2 / 2) / norm``, cut :func:`node_reach`."""
    if n == 1:
        return 0.0, 1.0, 1.0, trunc
    if n == 3:
        if q == 0:
            return 0.0, 2.0 / 3.0, 1.0, trunc
        t = math.sqrt(3.0) * kappa
        return (t if q == 1 else -t), 1.0, 6.0, trunc
    if n == 5:
        if q == 0:
            return 0.0, GH5_W[0], 1.0, trunc
        j = (q - 1) // 2
        t = GH5_T[j] * kappa
        return (t if q % 2 == 1 else -t), GH5_W[j + 1], 1.0, trunc
    tq = -trunc + 2.0 * trunc * q / (n - 1)
    return kappa * tq, math.exp(-0.5 * tq * tq), norm, node_reach(tq, trunc)


@njit_parallel
def _pndf_points(s_el, J, cx, cy, sp, qx, qy, sr, sh, trunc, lim2, out):
    """P-NDF at one point per footprint: the footprint-weighted mixture of the window's element
    Gaussians, each cut at ``2 trunc`` of its stds (Yan et al. 2016)."""
    H, W = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    cut = 8.0 * trunc * trunc
    for q in prange(out.shape[0]):
        x0, x1, y0, y1, f, var, tot2, wide = footprint_window(cx[q], cy[q], sp[q], sh2, trunc,
                                                              H, W, lim2)
        acc = 0.0
        wsum = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                c = x % W
                w = 1.0 if wide else math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
                wsum += w
                mx, my, a, b, d = element_gaussian(s_el, J, r, c, dx, dy, f, var, sr2)
                acc += w * element_density(qx[q] - mx, qy[q] - my, a, b, d, cut)
        out[q] = acc / wsum


@njit_serial
def splat(img, px, py, mx, my, siso, w, lo, h, trunc):
    """Add ``w`` times the pixel masses of ``N((mx, my), siso^2 I)``, cut at ``trunc siso`` per
    axis, to ``img (R, R)`` (separable erf). ``px``, ``py (R,)``: scratch of ``img``'s dtype, so
    the row update runs in it (float32 images: twice the lanes)."""
    R = img.shape[0]
    rad = trunc * siso
    j0 = max(0, int(math.floor((mx - rad - lo) / h)))
    j1 = min(R - 1, int(math.floor((mx + rad - lo) / h)))
    i0 = max(0, int(math.floor((my - rad - lo) / h)))
    i1 = min(R - 1, int(math.floor((my + rad - lo) / h)))
    if j0 > j1 or i0 > i1:
        return
    inv = 1.0 / siso
    prev = normal_cdf((lo + j0 * h - mx) * inv)
    for j in range(j0, j1 + 1):
        cur = normal_cdf((lo + (j + 1) * h - mx) * inv)
        px[j] = cur - prev
        prev = cur
    prev = normal_cdf((lo + i0 * h - my) * inv)
    for i in range(i0, i1 + 1):
        cur = normal_cdf((lo + (i + 1) * h - my) * inv)
        py[i] = w * (cur - prev)
        prev = cur
    # rows and columns as views indexed from 0: Numba then drops its negative-index branch and
    # LLVM vectorises the row update (level-0 NDF images ~2x faster than indexed loops,
    # benchmarks/bench_glints_bake.py; sums within 1 ulp)
    pxs = px[j0:j1 + 1]
    n = pxs.size
    for i in range(i0, i1 + 1):
        wy = py[i]
        row = img[i, j0:j1 + 1]
        for k in range(n):
            row[k] += wy * pxs[k]


@njit_inline
def node_reach(tk, trunc):  # pragma: no cover - compiled
    """Stds of the isotropic splat of a line node ``tk`` stds out along ``v``
    (:func:`splat_element`): the node carries ``exp(-tk^2 / 2)``, so its splat meets the
    element's cut ``exp(-trunc^2 / 2)`` at ``sqrt(trunc^2 - tk^2)`` (the nodes then cover the
    cut ellipse instead of the box around it: level-0 images of the render bake ~8 % faster, one
    timed cell); at least 1."""
    return math.sqrt(max(trunc * trunc - tk * tk, 1.0))


@njit_inline
def splat_element(img, px, py, mx, my, a, b, d, sr, w, lo, h, trunc):  # pragma: no cover
    """Add ``w`` times the pixel masses of an element's Gaussian ``N((mx, my), sr^2 I +
    [[a, b], [b, d]])`` to ``img (R, R)`` over ``[lo, lo + R h]^2`` (Yan et al. 2016 P-NDF
    elements), cut at ``trunc`` stds.

    The covariance is split exactly into an isotropic part ``siso^2 I`` (splatted with separable
    erf pixel masses) and a rank-one part ``kappa^2 v v^T`` (:func:`element_split`) integrated
    along ``v`` by equally spaced nodes (:func:`line_nodes`, :func:`node_count`: within ~3e-4 of
    the element's peak, further damped by the pixel box), or by 3- / 5-point Gauss-Hermite while
    ``kappa <= GH3_MAX / GH5_MAX siso``.
    ``px``, ``py (R,)``: scratch of ``img``'s dtype (:func:`splat`)."""
    R = img.shape[0]
    hi = lo + R * h
    nu1, siso, kappa = element_split(a, b, d, sr)
    reach = trunc * math.sqrt(nu1 + sr * sr)
    if mx + reach < lo or mx - reach > hi or my + reach < lo or my - reach > hi:
        return
    n, norm = element_nodes(kappa, siso, trunc)
    vx, vy = principal_axis(a, b, d, nu1) if n > 1 else (0.0, 0.0)
    for q in range(n):
        t, num, den, cut = element_node(kappa, trunc, n, norm, q)
        splat(img, px, py, mx + t * vx, my + t * vy, siso, w * num / den, lo, h, cut)


@njit_parallel
def _pndf_images(s_el, J, cx, cy, sp, sr, sh, trunc, ntrunc, lo, h, lim2, out):
    """NDF images ``out (N, R, R)`` float64 or float32: pixel averages of ``D_p`` (row = s_y,
    column = s_x; Yan et al. 2016), accumulated in ``out``'s dtype.

    ``trunc``: footprint weights cut at that many stds per axis; ``ntrunc``: each element's
    Gaussian in ``s`` cut at that many stds (:func:`splat_element`).
    """
    H, W = s_el.shape[0], s_el.shape[1]
    R = out.shape[1]
    sh2 = sh * sh
    for q in prange(out.shape[0]):
        img = out[q]
        px = np.zeros_like(img[0])
        py = np.zeros_like(img[0])
        x0, x1, y0, y1, f, var, tot2, wide = footprint_window(cx[q], cy[q], sp[q], sh2, trunc,
                                                              H, W, lim2)
        wsum = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                c = x % W
                w = 1.0 if wide else math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
                wsum += w
                mx, my, a, b, d = element_moments(s_el, J, r, c, dx, dy, f, var)
                splat_element(img, px, py, mx, my, a, b, d, sr, w, lo, h, ntrunc)
        scale = 1.0 / (wsum * h * h)
        for i in range(R):
            for j in range(R):
                img[i, j] *= scale


# ---------------------------------------------------------------------------------------------
# public API


def _prepared(normal_map, elements_=None):
    if elements_ is not None:
        # the kernels index these arrays without bounds checks: validate their layout here
        if not (isinstance(elements_, (tuple, list)) and len(elements_) == 2):
            raise PrefilterError("elements_: expected the pair (s, J) returned by elements(), got "
                                 f"{type(elements_).__name__}")
        s_el = as_float_array(elements_[0], "elements_[0] (s)", ndim_min=3, last_dim=2)
        J = as_float_array(elements_[1], "elements_[1] (J)", ndim_min=4)
        if s_el.ndim != 3 or J.shape != s_el.shape[:2] + (2, 2) or min(s_el.shape[:2]) < 2:
            raise PrefilterError(f"elements_: expected s (H, W, 2) and J (H, W, 2, 2) with "
                                 f"H, W >= 2, got {s_el.shape} and {J.shape}")
        return np.ascontiguousarray(s_el), np.ascontiguousarray(J)
    return elements(normal_map)


#: Footprints with ``sigma_p^2 + sigma_h^2 >= WIDE_FOOTPRINT^2`` (in tiles, at least
#: ``WIDE_MIN`` texels) use the sigma_p -> inf limit (:func:`footprint_window`).
WIDE_FOOTPRINT = 1.0
WIDE_MIN = 32.0


def wide_limit2(s_el) -> float:
    """``lim2`` of :func:`footprint_window` for elements ``s_el (H, W, 2)``: the squared total
    footprint std from which the sigma_p -> inf limit is used."""
    L = max(WIDE_FOOTPRINT * max(s_el.shape[0], s_el.shape[1]), WIDE_MIN)
    return float(L * L)


def pndf(normal_map, center, sigma_p, s, intrinsic_roughness: float = DEFAULT_ROUGHNESS, *,
         elements_=None) -> np.ndarray:
    """P-NDF ``D_p(s)`` of a Gaussian footprint, density w.r.t. projected normals ``s``.

    Yan et al. 2016, eq. for the P-NDF of a Gaussian footprint (closed-form element integrals).

    Parameters
    ----------
    normal_map : (H, W, 3) unit normals (periodic).
    center : (..., 2) footprint centres ``(x, y)`` in texels.
    sigma_p : (...) footprint standard deviations in texels.
    s : (..., 2) projected half vectors; ``center``, ``sigma_p`` and ``s`` broadcast together.
    intrinsic_roughness : std ``sigma_r`` of each element in ``s``.
    elements_ : optional precomputed ``elements(normal_map)`` (skips recomputing the Jacobians).

    Returns
    -------
    (...) densities; ``D(m) = D_p(m_xy)`` on the hemisphere (see module docstring).
    """
    s_el, J = _prepared(normal_map, elements_)
    sr = as_intrinsic_roughness(intrinsic_roughness)
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_sigma_p(sigma_p)
    q = as_float_array(s, "s", ndim_min=1, last_dim=2)
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape, s=q.shape[:-1])
    c = np.broadcast_to(c, shape + (2,)).reshape(-1, 2)
    q = np.broadcast_to(q, shape + (2,)).reshape(-1, 2)
    sp = kernel_array(sp, shape).reshape(-1)
    out = np.empty(c.shape[0])
    _pndf_points(s_el, J, np.ascontiguousarray(c[:, 0]), np.ascontiguousarray(c[:, 1]),
                 sp, np.ascontiguousarray(q[:, 0]),
                 np.ascontiguousarray(q[:, 1]), sr, SIGMA_H, TRUNCATION, wide_limit2(s_el), out)
    return out.reshape(shape)


def pndf_image(normal_map, center, sigma_p, resolution: int = 128, support: float = 0.5,
               intrinsic_roughness: float = DEFAULT_ROUGHNESS, *, elements_=None,
               ndf_truncation: float = TRUNCATION,
               footprint_truncation: float = TRUNCATION, dtype=np.float64) -> np.ndarray:
    """NDF images of Gaussian footprints: pixel averages of ``D_p`` over ``[-support, support]^2``.

    Yan et al. 2016 P-NDF, integrated exactly over each pixel (separable erf masses plus a
    spectrally accurate line quadrature along each element's principal axis).

    Parameters
    ----------
    normal_map : (H, W, 3) unit normals (periodic).
    center : (..., 2) footprint centres in texels; sigma_p : (...) footprint stds in texels.
    resolution : pixels per side ``R``; support : half-width of the square in ``s``.
    ndf_truncation : each element's Gaussian in ``s`` is cut at this many stds.
    footprint_truncation : the footprint weights are cut at this many stds per axis.
        The renderer's bakes use 6 for both (:data:`prefilter.glints.bake.BAKE_SETTINGS`):
        HDR-FLIP at the top exposures of a mostly black frame sees the tails beyond 4.
    dtype : float64 or float32, the images' and their sums' (float32: ~1.5x faster, within
        ~4e-6 of the float64 images relative to their peak; what the bakes store).

    Returns
    -------
    (..., R, R) images, row index along ``s_y``, column index along ``s_x``; the sum of an image
    times the pixel area ``(2 support / R)^2`` is the mass of ``D_p`` inside the square (<= 1).
    """
    s_el, J = _prepared(normal_map, elements_)
    sr = as_intrinsic_roughness(intrinsic_roughness)
    R = as_positive_int(resolution, "resolution")
    S = as_support(support)
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_sigma_p(sigma_p)
    nt = as_ndf_truncation(ndf_truncation)
    ft = as_ndf_truncation(footprint_truncation, "footprint_truncation")
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape)
    c = np.broadcast_to(c, shape + (2,)).reshape(-1, 2)
    sp = kernel_array(sp, shape).reshape(-1)
    dt = np.dtype(dtype)
    if dt not in (np.float64, np.float32):
        raise PrefilterError(f"dtype: expected float64 or float32, got {dt}")
    out = np.zeros((c.shape[0], R, R), dt)
    _pndf_images(s_el, J, np.ascontiguousarray(c[:, 0]), np.ascontiguousarray(c[:, 1]),
                 sp, sr, SIGMA_H, ft, nt, -S, 2.0 * S / R,
                 wide_limit2(s_el), out)
    return out.reshape(shape + (R, R))


def hemisphere_ndf(D_s, m) -> np.ndarray:
    """NDF ``D(m)`` on the hemisphere from P-NDF values ``D_s`` evaluated at ``s = m_xy``.

    ``D(m) = D_p(m_xy)`` for ``m_z > 0`` and 0 below (module docstring: both weight macro area),
    so ``integral D(m) m_z dm = integral D_p(s) ds``.
    """
    m = as_float_array(m, "m", ndim_min=1, last_dim=3)
    D = as_float_array(D_s, "D_s")
    return np.where(m[..., 2] > 0.0, D, 0.0)
