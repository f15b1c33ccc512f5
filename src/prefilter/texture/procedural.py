"""Seeded, periodic (tileable) procedural textures: normal maps, height maps and scalar noise.

Every generator works on a ``size x size`` torus (texel coordinates, texel centres at ``i + 0.5``),
so its output tiles seamlessly; the same ``(kind, size, seed, params)`` gives the same bytes.

Gaussian surfaces follow the standard construction of a Beckmann (Gaussian-statistics) surface:
white noise filtered in the Fourier domain by the square root of a Gaussian power spectrum. A
height correlation ``C(r) = sigma_h^2 exp(-r^T Q r)`` has the power spectrum
``P(k) ~ exp(-k^T Q^-1 k / 4)`` and the slope covariance ``Sigma = 2 sigma_h^2 Q``. Slopes are
computed analytically (spectral derivatives ``i k``), and the field is scaled so that the slope
covariance *of the discrete process* equals the requested one (an instance deviates from it by
sampling error only).

Conventions: heights are in texel units, so a slope ``s = grad h`` is dimensionless; the normal is
``n = normalize(-s_x, -s_y, 1)`` (tangent space, z up), i.e. ``s = (-n_x / n_z, -n_y / n_z)`` as in
the microfacet slope convention of ``equations.md`` section 1. For an isotropic Gaussian surface
``rms_slope = sqrt(E[s_x^2 + s_y^2])`` equals the Beckmann roughness ``alpha``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from prefilter.validation import (
    as_float_array,
    as_positive_int,
    as_rng,
    check_memory,
    check_scalar,
)
from prefilter.errors import PrefilterError

__all__ = [
    "HeightMap",
    "NORMAL_KINDS",
    "PARAMS",
    "HEIGHT_KINDS",
    "check_params",
    "height_map",
    "normal_map",
    "noise",
    "noise_level_variance",
    "noise_texture",
    "slopes_to_normals",
]


class HeightMap(NamedTuple):
    """A height field ``height (n, n)`` (texel units) and its exact slopes ``slopes (n, n, 2)``."""

    height: np.ndarray
    slopes: np.ndarray


# -- validation helpers -----------------------------------------------------------------------


#: Upper bounds of the procedural parameters without a natural one (lengths in texels, depths,
#: standard deviations): beyond them the spectra and slopes leave the float range.
LENGTH_MAX = 1e6
#: Largest rms slope (a normal 84 degrees from the surface normal on average).
RMS_SLOPE_MAX = 10.0
#: Most scratches of one ``scratches`` map (one vectorised pass each).
SCRATCHES_MAX = 100_000
#: Bytes per texel of the generators (white noise, its complex spectrum, the height, slope and
#: normal arrays and their temporaries) for the memory estimate.
BYTES_PER_TEXEL = 160


def _positive(x, name: str, *, lo: float = 0.0, hi: float = np.inf, closed: bool = False) -> float:
    return check_scalar(x, name, lo=lo, hi=hi, lo_open=not closed)


def _size(size) -> int:
    """The side of a procedural map (>= 4 texels) whose arrays fit the memory budget."""
    n = as_positive_int(size, "size", lo=4)
    check_memory(BYTES_PER_TEXEL * n * n, f"size: a procedural {n} x {n} map")
    return n


def _check_params(kind: str, params: dict, allowed: dict) -> dict:
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise PrefilterError(
            f"{kind}: unknown parameter(s) {', '.join(unknown)}; expected some of "
            f"{', '.join(sorted(allowed))}"
        )
    return {**allowed, **params}


def _slope_cov(cov, name: str = "cov") -> np.ndarray:
    c = as_float_array(cov, name)
    if c.shape != (2, 2) or not np.allclose(c, c.T, rtol=0, atol=1e-12):
        raise PrefilterError(f"{name}: expected a symmetric 2x2 matrix, got {c.tolist()!r}")
    if np.any(np.abs(c) > RMS_SLOPE_MAX**2):
        raise PrefilterError(f"{name}: expected entries of magnitude <= {RMS_SLOPE_MAX**2:g} "
                             f"(rms slope {RMS_SLOPE_MAX:g}), got {c.tolist()!r}")
    if np.linalg.eigvalsh(c)[0] <= 0.0:
        raise PrefilterError(f"{name}: expected a positive definite covariance, got {c.tolist()!r}")
    return c


# -- the Gaussian random field ------------------------------------------------------------------


def _freqs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Angular frequencies ``(kx, ky)`` of an ``n x n`` DFT (array axis 0 = y, axis 1 = x)."""
    k = 2.0 * np.pi * np.fft.fftfreq(n)
    return k[None, :], k[:, None]


def _derivative_factors(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Spectral derivative multipliers ``i kx``, ``i ky``; zero at Nyquist, where a real field has
    no well-defined derivative (its ``i k`` term would not be Hermitian)."""
    kx, ky = _freqs(n)
    if n % 2 == 0:
        kx = kx.copy()
        ky = ky.copy()
        kx[:, n // 2] = 0.0
        ky[n // 2, :] = 0.0
    return 1j * kx, 1j * ky


def _gaussian_amplitude(n: int, q: np.ndarray) -> np.ndarray:
    """Square root of the power spectrum of ``C(r) = exp(-r^T q r)``: ``exp(-k^T q^-1 k / 8)``."""
    kx, ky = _freqs(n)
    qi = np.linalg.inv(q)
    quad = qi[0, 0] * kx * kx + 2.0 * qi[0, 1] * kx * ky + qi[1, 1] * ky * ky
    return np.exp(-quad / 8.0)


def _discrete_slope_cov(amp: np.ndarray) -> np.ndarray:
    """Slope covariance of the discrete process ``ifft(fft(white) * amp)`` with derivatives."""
    n = amp.shape[0]
    dx, dy = _derivative_factors(n)
    p = amp * amp / amp.size  # E|fft(white)|^2 = N, and ifft divides by N
    cxx = np.sum(p * np.abs(dx) ** 2)
    cyy = np.sum(p * np.abs(dy) ** 2)
    cxy = np.sum(p * np.real(dx * np.conj(dy)))
    return np.array([[cxx, cxy], [cxy, cyy]])


def _gaussian_surface(n: int, rng: np.random.Generator, cov: np.ndarray, corr_length: float):
    """Gaussian height field with slope covariance ``cov`` and geometric-mean correlation length
    ``corr_length`` (texels), returned as a :class:`HeightMap`.

    With ``C(r) = sigma_h^2 exp(-r^T Q r)`` and ``Sigma = 2 sigma_h^2 Q``, the correlation lengths
    along the eigenvectors are ``l_i = 1 / sqrt(q_i)``; choosing ``sqrt(l_1 l_2) = corr_length``
    fixes ``sigma_h^2 = corr_length^2 sqrt(det Sigma) / 2``.
    """
    sigma_h2 = corr_length**2 * np.sqrt(np.linalg.det(cov)) / 2.0
    q = cov / (2.0 * sigma_h2)
    amp = _gaussian_amplitude(n, q)
    # Rescale so the discrete process has exactly the requested slope variance (trace); the
    # residual shape error of the sampled spectrum is negligible for correlation lengths >= 2.
    amp *= np.sqrt(np.trace(cov) / np.trace(_discrete_slope_cov(amp)))
    spec = np.fft.fft2(rng.standard_normal((n, n))) * amp
    dx, dy = _derivative_factors(n)
    height = np.fft.ifft2(spec).real
    sx = np.fft.ifft2(spec * dx).real
    sy = np.fft.ifft2(spec * dy).real
    return HeightMap(height, np.stack([sx, sy], axis=-1))


def slopes_to_normals(slopes) -> np.ndarray:
    """Unit tangent-space normals ``(..., 3)`` from height slopes ``(..., 2)``:
    ``normalize(-s_x, -s_y, 1)``."""
    s = as_float_array(slopes, "slopes", ndim_min=1, last_dim=2)
    n = np.concatenate([-s, np.ones(s.shape[:-1] + (1,))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


# -- height maps ----------------------------------------------------------------------------

_GAUSSIAN = {"rms_slope": 0.3, "corr_length": 8.0}
_ANISO = {"cov": ((0.09, 0.0), (0.0, 0.01)), "corr_length": 8.0}
_BRUSHED = {"rms_slope": 0.2, "length": 64.0, "width": 1.5}
HEIGHT_KINDS = ("gaussian", "anisotropic", "brushed")


#: Longest correlation length of a Gaussian surface, in map sizes: at ``corr_length / size = 8``
#: the slope spectrum of the torus underflows (slopes would be NaN); at 4 it is 1e-69.
CORR_LENGTH_MAX = 4


def _corr_length(x, n: int, name: str = "corr_length") -> float:
    """A correlation length in (0.5, CORR_LENGTH_MAX * n] texels."""
    return _positive(x, name, lo=0.5, hi=float(CORR_LENGTH_MAX * n))


def _height_values(kind: str, n: int, params: dict) -> tuple[np.ndarray, float]:
    """The slope covariance and correlation length of a Gaussian height kind, its parameters
    checked."""
    if kind == "gaussian":
        p = _check_params(kind, params, _GAUSSIAN)
        a = _positive(p["rms_slope"], "rms_slope", hi=RMS_SLOPE_MAX)
        return np.eye(2) * a * a / 2.0, _corr_length(p["corr_length"], n)
    if kind == "anisotropic":
        p = _check_params(kind, params, _ANISO)
        return _slope_cov(p["cov"]), _corr_length(p["corr_length"], n)
    if kind == "brushed":
        # Grooves along x: long correlation along x, short across y. Slope covariance is
        # diag(l_y^2, l_x^2) * const (Sigma = 2 sigma_h^2 Q with Q = diag(1/l_x^2, 1/l_y^2)).
        p = _check_params(kind, params, _BRUSHED)
        a = _positive(p["rms_slope"], "rms_slope", hi=RMS_SLOPE_MAX)
        lx = _positive(p["length"], "length", lo=0.5, hi=LENGTH_MAX)
        ly = _positive(p["width"], "width", lo=0.5, hi=LENGTH_MAX)
        if min(lx, ly) > CORR_LENGTH_MAX * n:  # as _corr_length, for one of the two axes
            raise PrefilterError(f"width: expected length or width <= {CORR_LENGTH_MAX * n} "
                                 f"({CORR_LENGTH_MAX} x size), got length {lx:g} and width "
                                 f"{ly:g}")
        w = np.array([ly * ly, lx * lx])
        return np.diag(a * a * w / w.sum()), float(np.sqrt(lx * ly))
    raise PrefilterError(f"kind: expected one of {', '.join(HEIGHT_KINDS)}, got {kind!r}")


def _height(kind: str, n: int, rng: np.random.Generator, params: dict) -> HeightMap:
    return _gaussian_surface(n, rng, *_height_values(kind, n, params))


def height_map(kind: str = "gaussian", size: int = 512, seed=0, **params) -> HeightMap:
    """Periodic Gaussian height field and its analytic slopes.

    Parameters
    ----------
    kind : {"gaussian", "anisotropic", "brushed"}
        ``gaussian``: isotropic, ``rms_slope`` (= Beckmann alpha, default 0.3, at most
        :data:`RMS_SLOPE_MAX`) and ``corr_length`` (texels, default 8, in (0.5, 4 size]).
        ``anisotropic``: slope covariance ``cov`` (2x2, default ``diag(0.09, 0.01)``, entries
        at most ``RMS_SLOPE_MAX^2``) and geometric-mean ``corr_length``. ``brushed``:
        ``rms_slope``, ``length`` (correlation length along x, default 64) and ``width`` (across
        y, default 1.5), each in (0.5, :data:`LENGTH_MAX`], the shorter at most ``4 size``.
    size : int
        Side in texels (its arrays must fit :func:`prefilter.validation.check_memory`).
    seed : int or numpy.random.Generator

    Returns
    -------
    HeightMap
        ``height (size, size)`` in texel units (row = y, column = x) and
        ``slopes (size, size, 2)`` = ``(dh/dx, dh/dy)``, float64.
    """
    n = _size(size)
    return _height(kind, n, as_rng(seed, "seed"), dict(params))


# -- normal maps ----------------------------------------------------------------------------

_SCRATCHES = {"count": 60, "width": 1.0, "depth": 1.0, "length": 0.3, "base_rms_slope": 0.0}
_FLAKES = {"flake_size": 8.0, "rms_slope": 0.3}
NORMAL_KINDS = ("gaussian", "anisotropic", "brushed", "scratches", "flakes")
_NOISE = {"corr_length": 4.0, "sigma": 1.0}
#: Parameter names of every procedural kind (``noise`` is the scalar noise of :func:`noise`).
PARAMS = {k: tuple(p) for k, p in (("gaussian", _GAUSSIAN), ("anisotropic", _ANISO),
                                   ("brushed", _BRUSHED), ("scratches", _SCRATCHES),
                                   ("flakes", _FLAKES), ("noise", _NOISE))}


def _scratch_values(n: int, p: dict) -> tuple[int, float, float, float, float]:
    """``count, width, depth, length`` (texels) and ``base_rms_slope`` of a scratches map."""
    count = as_positive_int(p["count"], "count", lo=0, hi=SCRATCHES_MAX)
    w = _positive(p["width"], "width", lo=0.1, hi=float(n))
    depth = _positive(p["depth"], "depth", lo=0.0, closed=True, hi=LENGTH_MAX)
    length = _positive(p["length"], "length", hi=1.0) * n
    base = _positive(p["base_rms_slope"], "base_rms_slope", lo=0.0, closed=True,
                     hi=RMS_SLOPE_MAX)
    return count, w, depth, length, base


def _scratch_slopes(n: int, rng: np.random.Generator, p: dict) -> np.ndarray:
    """Slopes of a sum of Gaussian-profile grooves along random segments (periodic).

    A groove ``h = -depth exp(-d^2 / (2 width^2))`` with ``d`` the distance to the segment has the
    gradient ``depth exp(-d^2 / (2 width^2)) (p - c) / width^2`` (``c`` the closest point).
    """
    count, w, depth, length, base = _scratch_values(n, p)
    # Draw all scratch parameters up front so the stream does not depend on the loop below.
    centre = rng.uniform(0.0, n, (count, 2))
    angle = rng.uniform(0.0, np.pi, count)
    frac = rng.uniform(0.3, 1.0, count)
    slopes = np.zeros((n, n, 2))
    if base > 0.0:
        slopes += _gaussian_surface(n, rng, np.eye(2) * base * base / 2.0, 4.0).slopes
    reach = 4.0 * w
    for c, th, f in zip(centre, angle, frac):  # one vectorised pass per scratch (bounding box)
        half = 0.5 * f * length * np.array([np.cos(th), np.sin(th)])
        a, b = c - half, c + half
        lo = np.floor(np.minimum(a, b) - reach).astype(int)
        hi = np.ceil(np.maximum(a, b) + reach).astype(int)
        ix = np.arange(lo[0], hi[0] + 1)
        iy = np.arange(lo[1], hi[1] + 1)
        px, py = np.meshgrid(ix + 0.5, iy + 0.5)
        pts = np.stack([px, py], axis=-1)
        ab = b - a
        t = np.clip(((pts - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
        d = pts - (a + t[..., None] * ab)
        g = depth * np.exp(-np.sum(d * d, -1) / (2 * w * w))[..., None] * d / (w * w)
        # Accumulate with wrap-around; np.add.at handles boxes wider than the texture.
        np.add.at(slopes, (np.mod(iy, n)[:, None], np.mod(ix, n)[None, :]), g)
    return slopes


def _flake_values(n: int, p: dict) -> tuple[float, float]:
    """``flake_size`` (texels; larger than the map: one flake) and ``rms_slope`` of a flakes
    map."""
    return (_positive(p["flake_size"], "flake_size", lo=1.0, hi=LENGTH_MAX),
            _positive(p["rms_slope"], "rms_slope", lo=0.0, closed=True, hi=RMS_SLOPE_MAX))


def _flake_slopes(n: int, rng: np.random.Generator, p: dict) -> np.ndarray:
    """Voronoi cells (one jittered site per grid cell), each with a Gaussian random slope."""
    cell, a = _flake_values(n, p)
    g = max(1, int(round(n / cell)))
    cs = n / g  # cell size adjusted so the grid tiles the texture exactly
    site = rng.uniform(0.0, 1.0, (g, g, 2))
    flake = rng.standard_normal((g, g, 2)) * (a / np.sqrt(2.0))
    centres = np.arange(n) + 0.5
    px, py = np.meshgrid(centres, centres)
    cx, cy = np.floor(px / cs).astype(int), np.floor(py / cs).astype(int)
    best = np.full((n, n), np.inf)
    owner = np.zeros((n, n, 2), dtype=int)
    for oy in (-1, 0, 1):
        for ox in (-1, 0, 1):
            jx, jy = cx + ox, cy + oy
            wx, wy = np.mod(jx, g), np.mod(jy, g)
            sx = (jx + site[wy, wx, 0]) * cs
            sy = (jy + site[wy, wx, 1]) * cs
            d2 = (px - sx) ** 2 + (py - sy) ** 2
            closer = d2 < best
            best = np.where(closer, d2, best)
            owner[closer] = np.stack([wy, wx], -1)[closer]
    return flake[owner[..., 0], owner[..., 1]]


def normal_map(kind: str = "gaussian", size: int = 512, seed=0, **params) -> np.ndarray:
    """Periodic tangent-space normal map ``(size, size, 3)`` of unit normals (z up), float64.

    Parameters
    ----------
    kind : {"gaussian", "anisotropic", "brushed", "scratches", "flakes"}
        The first three are the Gaussian surfaces of :func:`height_map` (same parameters).
        ``scratches``: ``count`` (60) random line grooves of Gaussian profile, ``width`` (texels,
        1), ``depth`` (texels, 1), ``length`` (max length as a fraction of the texture, 0.3) on a
        flat base (or a Gaussian base with ``base_rms_slope`` > 0).
        ``flakes``: Voronoi cells of mean diameter ``flake_size`` (texels, 8; one cell when it
        exceeds ``size``), each flat with a random slope drawn from ``N(0, rms_slope^2 / 2 I)``
        (so ``E|s|^2 = rms_slope^2``).
    size : int
        Side in texels (row index = v = y, column index = u = x).
    seed : int or numpy.random.Generator

    Returns
    -------
    numpy.ndarray
        ``(size, size, 3)`` float64 unit vectors.
    """
    n = _size(size)
    rng = as_rng(seed, "seed")
    params = dict(params)
    if kind in HEIGHT_KINDS:
        slopes = _height(kind, n, rng, params).slopes
    elif kind == "scratches":
        slopes = _scratch_slopes(n, rng, _check_params(kind, params, _SCRATCHES))
    elif kind == "flakes":
        slopes = _flake_slopes(n, rng, _check_params(kind, params, _FLAKES))
    else:
        raise PrefilterError(f"kind: expected one of {', '.join(NORMAL_KINDS)}, got {kind!r}")
    return slopes_to_normals(slopes)


# -- scalar noise -----------------------------------------------------------------------------


def _noise_power(n: int, corr_length: float) -> np.ndarray:
    """Per-frequency variance ``P(k) / N`` of the unit-variance Gaussian noise process."""
    amp = _gaussian_amplitude(n, np.eye(2) / corr_length**2)
    p = amp * amp
    return p / p.sum()


def _noise_values(corr_length, sigma) -> tuple[float, float]:
    return (_positive(corr_length, "corr_length", lo=0.25, hi=LENGTH_MAX),
            _positive(sigma, "sigma", lo=0.0, closed=True, hi=LENGTH_MAX))


def noise(size: int = 512, seed=0, corr_length: float = 4.0, sigma: float = 1.0) -> np.ndarray:
    """Periodic zero-mean Gaussian noise ``(size, size)`` with variance ``sigma^2``.

    The correlation is ``C(r) = sigma^2 exp(-r^2 / corr_length^2)`` (``corr_length`` in texels),
    sampled on the torus; the variance of every texel of every box-filtered mip level is given by
    :func:`noise_level_variance`.
    """
    n = _size(size)
    rng = as_rng(seed, "seed")
    l, s = _noise_values(corr_length, sigma)
    # fft of unit white noise has E|W|^2 = N; with p summing to 1, ifft gives unit variance.
    amp = np.sqrt(_noise_power(n, l) * n * n)
    return s * np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * amp).real


def noise_texture(size: int = 512, seed=0, corr_length: float = 4.0,
                  sigma: float = 1.0) -> np.ndarray:
    """:func:`noise` as a colour or radiance texture ``(size, size)`` in ``[0, 1]``:
    ``clip(0.5 + 0.5 * noise, 0, 1)``.

    Mean 0.5 and standard deviation ``sigma / 2`` where nothing is clipped (``sigma <= 1/3``
    clips 0.3 % of texels; the default ``sigma = 1`` clips 32 %, at 0 and 1). Used for procedural
    ``color_map``, ``light_texture`` and ``environment`` textures of scenes, which multiply
    light and must not be negative (the zero-mean :func:`noise` would give negative pixels).
    """
    return np.clip(0.5 + 0.5 * noise(size, seed, corr_length, sigma), 0.0, 1.0)


def noise_level_variance(size: int = 512, corr_length: float = 4.0, sigma: float = 1.0):
    """Variance of the texels of each mip level of :func:`noise` (2x2 box averaging).

    Level ``L`` texels are averages of aligned ``m x m`` blocks, ``m = 2^L``: the noise filtered by
    the box ``b_L`` and decimated. Decimation does not change a stationary field's marginal, so

        Var_L = sigma^2 sum_k P(k) |B_L(k)|^2,   B_L(k) = prod_axes sin(m k / 2) / (m sin(k / 2)),

    with ``P`` the discrete power spectrum of :func:`noise` (normalised to sum 1) and ``B_L`` the
    DFT of the box (a Dirichlet kernel). This is exact for the generating process. The variance
    of the noise *within* a level-L footprint (what a colour map filter needs) is
    ``sigma^2 - Var_L`` (law of total variance over the aligned blocks).

    Returns
    -------
    numpy.ndarray
        ``(log2(size) + 1,)`` variances, level 0 first (``Var_0 = sigma^2``).
    """
    n = _size(size)
    if n & (n - 1):
        raise PrefilterError(f"size: expected a power of two for mip levels, got {n}")
    l, s = _noise_values(corr_length, sigma)
    p = _noise_power(n, l)
    k = 2.0 * np.pi * np.fft.fftfreq(n)
    out = []
    for level in range(int(np.log2(n)) + 1):
        m = 2**level
        with np.errstate(invalid="ignore", divide="ignore"):
            b = np.where(k == 0.0, 1.0, np.sin(m * k / 2.0) / (m * np.sin(k / 2.0)))
        out.append(s * s * np.sum(p * (b[None, :] * b[:, None]) ** 2))
    return np.array(out)


def check_params(kind: str, size: int, **params) -> None:
    """Check a procedural texture's parameters without generating it (a PrefilterError naming
    the parameter, as the generators give): ``kind`` one of :data:`NORMAL_KINDS`,
    :data:`HEIGHT_KINDS` or ``"noise"``; ``size`` the side in texels."""
    n = _size(size)
    params = dict(params)
    if kind in HEIGHT_KINDS:
        _height_values(kind, n, params)
    elif kind == "scratches":
        _scratch_values(n, _check_params(kind, params, _SCRATCHES))
    elif kind == "flakes":
        _flake_values(n, _check_params(kind, params, _FLAKES))
    elif kind == "noise":
        p = _check_params(kind, params, _NOISE)
        _noise_values(p["corr_length"], p["sigma"])
    else:
        raise PrefilterError(f"kind: expected one of {', '.join(NORMAL_KINDS + ('noise',))}, "
                             f"got {kind!r}")
