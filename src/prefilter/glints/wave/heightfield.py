"""Heightfields for wave-optics glints: heights in metres on a periodic grid of stated texel size.

A heightfield is ``(H, W)`` heights ``h`` in metres sampled at texel centres
``u = (col + 0.5, row + 0.5)`` (texel units, as the normal maps of :mod:`prefilter.glints.pndf`),
``texel_size`` metres apart, periodic (a tile). Between samples it is the band-limited (Fourier)
interpolation of the samples: the wave integral resamples it finer (:func:`upsampled`) and its
normals come from spectral derivatives (:func:`normal_map`), so both see the same surface.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.validation import as_positive_int, check_scalar

#: Units of heights given as numbers: metres, or texel units (multiplied by the texel size).
UNITS = ("m", "texel")


@dataclass(frozen=True)
class Heightfield:
    """Heights ``(H, W)`` in metres, ``texel_size`` metres per texel (periodic)."""

    heights: np.ndarray
    texel_size: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def digest(self) -> str:
        """SHA-1 of the heights and texel size (what bakes and caches are keyed by)."""
        h = hashlib.sha1(np.ascontiguousarray(self.heights, np.float64).tobytes())
        h.update(repr(float(self.texel_size)).encode())
        return h.hexdigest()


def heightfield(heights, texel_size, units: str = "m", name: str = "heights") -> Heightfield:
    """A validated :class:`Heightfield`.

    Parameters
    ----------
    heights : (H, W) finite numbers, H, W >= 2 (a Heightfield is returned as it is).
    texel_size : metres per texel, > 0.
    units : ``"m"`` (heights in metres) or ``"texel"`` (in texel units: times ``texel_size``).
    """
    if isinstance(heights, Heightfield):
        return heights
    dx = check_scalar(texel_size, "texel_size", lo=0.0, lo_open=True)
    if units not in UNITS:
        raise PrefilterError(f"units: expected one of {', '.join(UNITS)}, got {units!r}")
    try:
        a = np.asarray(heights)
    except (TypeError, ValueError):
        raise PrefilterError(f"{name}: expected a numeric (H, W) array, got "
                             f"{type(heights).__name__}") from None
    if a.dtype.kind not in "biuf" or a.dtype == np.bool_:
        raise PrefilterError(f"{name}: expected a numeric (H, W) array, got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise PrefilterError(f"{name}: expected shape (H, W), got shape {a.shape}")
    if min(a.shape) < 2:
        raise PrefilterError(f"{name}: expected at least 2 x 2 texels, got shape {a.shape}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise PrefilterError(f"{name}: expected finite heights, got "
                             f"{int(np.count_nonzero(~np.isfinite(a)))} NaN or inf values")
    if units == "texel":
        a = a * dx
    return Heightfield(np.ascontiguousarray(a), dx)


def read_heightfield(path, texel_size, units: str = "m", height_scale: float = 1.0) -> Heightfield:
    """A heightfield from an image (first channel, PNG values in [0, 1]) or ``.npy``, its values
    times ``height_scale`` in ``units``."""
    from prefilter.texture.io import read_image

    scale = check_scalar(height_scale, "height_scale", lo=0.0)
    img = read_image(Path(path))
    return heightfield(img[..., 0] * scale, texel_size, units, name=f"heights ({path})")


def isotropic_noise(size: int = 256, *, rms: float = 0.05e-6, correlation: float = 4.0,
                    texel_size: float = 0.25e-6, seed: int = 0) -> Heightfield:
    """Periodic Gaussian random heights with a Gaussian autocorrelation.

    ``rms`` metres of height, ``correlation`` texels: the autocorrelation is
    ``rms^2 exp(-|d|^2 / correlation^2)`` (white noise filtered by a Gaussian of std
    ``correlation / 2``), so the rms slope per axis is ``sqrt(2) rms / (correlation dx)``.
    """
    n = as_positive_int(size, "size", lo=2)
    check_scalar(rms, "rms", lo=0.0)
    corr = check_scalar(correlation, "correlation", lo=0.0, lo_open=True)
    rng = np.random.default_rng(as_positive_int(seed, "seed", lo=0))
    f = np.fft.fftfreq(n)
    g = corr / 2.0
    filt = np.exp(-2.0 * math.pi**2 * g * g * (f[:, None] ** 2 + f[None, :] ** 2))
    h = np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * filt).real
    h *= rms / max(h.std(), 1e-300)
    return heightfield(h - h.mean(), texel_size)


def scratches(size: int = 256, *, count: int = 40, depth: float = 0.15e-6, width: float = 1.5,
              texel_size: float = 0.25e-6, seed: int = 0) -> Heightfield:
    """Periodic straight scratches: Gaussian grooves ``-depth exp(-d^2 / (2 width^2))`` (``d`` in
    texels) along lines that wrap around the tile (directions ``(a, b)`` tiles, small integers)."""
    n = as_positive_int(size, "size", lo=2)
    k = as_positive_int(count, "count", lo=0)
    check_scalar(depth, "depth", lo=0.0)
    w = check_scalar(width, "width", lo=0.0, lo_open=True)
    rng = np.random.default_rng(as_positive_int(seed, "seed", lo=0))
    y, x = np.mgrid[0:n, 0:n] + 0.5
    h = np.zeros((n, n))
    dirs = [(a, b) for a in range(-3, 4) for b in range(0, 4)
            if (b > 0 or a > 0) and math.gcd(a, b) == 1]
    for _ in range(k):
        a, b = dirs[rng.integers(len(dirs))]
        v = np.array([a, b], float) * n
        nrm = np.array([-v[1], v[0]]) / np.hypot(*v)
        spacing = n * n / np.hypot(*v)  # the wraps of one line are parallel lines this far apart
        p = rng.uniform(0, n, 2)
        d = ((x - p[0]) * nrm[0] + (y - p[1]) * nrm[1]) % spacing
        d = np.minimum(d, spacing - d)
        h -= depth * rng.uniform(0.5, 1.0) * np.exp(-0.5 * (d / w) ** 2)
    return heightfield(h - h.mean(), texel_size)


PROCEDURAL = {"noise": isotropic_noise, "scratches": scratches}


def procedural(spec: str) -> Heightfield:
    """``KIND[:SIZE[:SEED]]`` with KIND in :data:`PROCEDURAL` (default parameters otherwise)."""
    kind, *rest = str(spec).split(":")
    if kind not in PROCEDURAL or len(rest) > 2:
        raise PrefilterError(f"heightfield: expected KIND[:SIZE[:SEED]] with KIND one of "
                             f"{', '.join(PROCEDURAL)}, got {spec!r}")
    try:
        args = [int(v) for v in rest]
    except ValueError:
        raise PrefilterError(f"heightfield: expected integer SIZE and SEED, got {spec!r}") from None
    return PROCEDURAL[kind](*args[:1], **({"seed": args[1]} if len(args) > 1 else {}))


def gradient(hf: Heightfield) -> np.ndarray:
    """Slopes ``(H, W, 2)`` = ``(dh/dx, dh/dy)`` (dimensionless) by spectral differentiation."""
    H, W = hf.shape
    F = np.fft.fft2(hf.heights)
    kx = 2j * math.pi * np.fft.fftfreq(W)[None, :]
    ky = 2j * math.pi * np.fft.fftfreq(H)[:, None]
    if W % 2 == 0:  # the Nyquist term's derivative is not real: drop it
        kx[:, W // 2] = 0
    if H % 2 == 0:
        ky[H // 2, :] = 0
    gx = np.fft.ifft2(F * kx).real / hf.texel_size
    gy = np.fft.ifft2(F * ky).real / hf.texel_size
    return np.stack([gx, gy], axis=-1)


def normal_map(hf: Heightfield) -> np.ndarray:
    """Unit normals ``(H, W, 3)`` ``(-h_x, -h_y, 1) / norm`` of the heightfield: the input of the
    geometric P-NDF (:func:`prefilter.glints.pndf.pndf_image`) of the same surface."""
    g = gradient(hf)
    n = np.concatenate([-g, np.ones(g.shape[:2] + (1,))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def upsampled(hf: Heightfield, factor: int) -> np.ndarray:
    """Band-limited interpolation ``(H f, W f)`` of the heights: sample ``[i, j]`` lies at
    ``u = (0.5 + j / f, 0.5 + i / f)`` texels (zero padding of the spectrum)."""
    f = as_positive_int(factor, "factor")
    if f == 1:
        return hf.heights.copy()
    H, W = hf.shape
    F = np.fft.fftshift(np.fft.fft2(hf.heights))
    P = np.zeros((H * f, W * f), complex)
    y0, x0 = (H * f) // 2 - H // 2, (W * f) // 2 - W // 2
    P[y0:y0 + H, x0:x0 + W] = F
    if H % 2 == 0:  # split the Nyquist row / column evenly (a real, symmetric interpolant)
        P[y0, :] *= 0.5
        P[y0 + H, :] = P[y0, :]
    if W % 2 == 0:
        P[:, x0] *= 0.5
        P[:, x0 + W] = P[:, x0]
    # the samples sit at texel centres (+0.5): the interpolant is shifted by -0.5 texel before
    # sampling at 0.5 + j / f, i.e. sample the spectrum at offsets j / f
    return np.fft.ifft2(np.fft.ifftshift(P)).real * f * f
