"""Periodic mip chains, moments mips and footprint-driven (trilinear / anisotropic) lookups.

Level ``l`` averages aligned ``2^l x 2^l`` blocks of level 0 (2x2 box averaging; textures tile).
Averages of normals are kept *unnormalised*: their length shrinks where normals disagree, which
multi-scale LTC and LEAN/LEADR-style methods need (``equations.md`` section 4). Moments mips store
``E[x], E[x^2]`` of a scalar map or ``E[x], E[y], E[x^2], E[y^2], E[xy]`` of a 2D slope map, so a
lookup gives the mean and (co)variance over the footprint (Olano & Baker 2010; Heitz et al. 2015
section 5 for colour maps).

Texture coordinates: ``u`` along columns, ``v`` along rows, texel ``(i, j)`` centred at
``((j + 0.5) / W, (i + 0.5) / H)``; lookups wrap (period 1 in u and v).
"""

from __future__ import annotations

import functools

import numpy as np

from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.jit import serial
from prefilter.texture.fetch import footprint_axes_kernel, pack_levels, trilinear

__all__ = ["MipChain", "footprint_axes", "lod_from_footprint", "moment_chain", "moments_to_stats"]


def _is_pow2(n: int) -> bool:
    return n >= 1 and (n & (n - 1)) == 0


def _continue_chain(levels: list) -> list:
    """``levels`` extended by 2x2 box averages of its last level down to ``1 x 1``."""
    a = levels[-1]
    while a.shape[0] > 1 or a.shape[1] > 1:
        if a.shape[0] > 1:
            a = 0.5 * (a[0::2] + a[1::2])
        if a.shape[1] > 1:
            a = 0.5 * (a[:, 0::2] + a[:, 1::2])
        levels.append(a)
    return levels


class MipChain:
    """Box-filtered periodic pyramid of an ``(H, W)`` or ``(H, W, C)`` texture (powers of two).

    Attributes
    ----------
    levels : list of numpy.ndarray
        ``levels[l]`` has shape ``(max(H >> l, 1), max(W >> l, 1), C)``, float64; the last level
        is ``1 x 1`` (the texture mean).
    """

    def __init__(self, image):
        a = as_float_array(image, "image", ndim_min=2)
        if a.ndim == 2:
            a = a[..., None]
        if a.ndim != 3:
            raise PrefilterError(f"image: expected shape (H, W) or (H, W, C), got {a.shape}")
        h, w = a.shape[:2]
        if not (_is_pow2(h) and _is_pow2(w)):
            raise PrefilterError(f"image: expected power-of-two height and width, got {h} x {w}")
        self.levels = _continue_chain([a])

    @classmethod
    def from_levels(cls, levels) -> "MipChain":
        """The chain whose first levels are ``levels`` (each the box average of the one before,
        computed elsewhere, e.g. band by band), continued down to ``1 x 1`` from the last."""
        chain = cls.__new__(cls)
        chain.levels = _continue_chain([np.asarray(lv, np.float64) for lv in levels])
        return chain

    @property
    def n_levels(self) -> int:
        return len(self.levels)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape ``(H, W, C)`` of level 0."""
        return self.levels[0].shape

    def __repr__(self) -> str:
        return f"MipChain(shape={self.shape}, n_levels={self.n_levels})"

    @functools.cached_property
    def packed(self):
        """The levels packed for compiled lookups (:func:`prefilter.texture.fetch.pack_levels`)."""
        return pack_levels(self.levels)

    def lookup(self, uv, lod=0.0) -> np.ndarray:
        """Trilinear lookup: bilinear in the two levels around ``lod``, linear between them
        (:func:`prefilter.texture.fetch.trilinear`).

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Texture coordinates (wrapped).
        lod : array_like, shape (...)
            Level of detail; clamped to ``[0, n_levels - 1]``.

        Returns
        -------
        numpy.ndarray, shape (..., C)
        """
        uv = as_float_array(uv, "uv", ndim_min=1, last_dim=2)
        lod = np.broadcast_to(as_float_array(lod, "lod"), uv.shape[:-1])
        return trilinear(self.packed, uv, lod)

    def lookup_footprint(self, uv, dudv, *, anisotropic: bool = False, max_aniso: int = 8):
        """Filtered lookup over a pixel footprint given by the Jacobian ``dudv = d(uv)/d(pixel)``.

        Isotropic: one trilinear tap at ``lod = log2(major axis in texels)``. Anisotropic (as GPUs
        do): ``N = min(ceil(major / minor), max_aniso)`` trilinear taps spread along the major axis
        at ``lod = log2(max(minor, major / max_aniso))``, averaged.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
        dudv : array_like, shape (..., 2, 2)
            ``dudv[..., a, b] = d uv_a / d pixel_b`` (pixel axes x = column, y = row).

        Returns
        -------
        numpy.ndarray, shape (..., C)
        """
        uv = as_float_array(uv, "uv", ndim_min=1, last_dim=2)
        h, w = self.shape[:2]
        major, minor, direction = footprint_axes(dudv, (h, w))
        if not anisotropic:
            return self.lookup(uv, _log2_lod(major))
        k = as_positive_int(max_aniso, "max_aniso")
        with np.errstate(divide="ignore"):
            taps = np.clip(np.ceil(major / np.maximum(minor, 1e-300)), 1, k).astype(np.int64)
        lod = _log2_lod(np.maximum(minor, major / k))
        # the major axis in uv units: `direction` is a unit vector in texel space
        axis_uv = direction * (major[..., None] / np.array([w, h], float))
        out = np.zeros(uv.shape[:-1] + (self.shape[2],))
        for n in np.unique(taps):
            m = taps == n
            for i in range(n):
                offset = ((i + 0.5) / n - 0.5) * axis_uv[m]
                out[m] += self.lookup(uv[m] + offset, lod[m]) / n
        return out


def _log2_lod(length_texels: np.ndarray) -> np.ndarray:
    return np.log2(np.maximum(length_texels, 1.0))


def footprint_axes(dudv, shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ellipse axes of a pixel footprint in texels.

    The Jacobian in texel units ``J = diag(W, H) dudv`` maps the unit pixel to a parallelogram;
    its singular values are the major and minor axis lengths of the footprint ellipse, and the
    left singular vector of the largest one is the major direction (in texel space); computed by
    :func:`prefilter.texture.fetch.footprint_axes_jit`, which kernels call.

    Parameters
    ----------
    dudv : array_like, shape (..., 2, 2)
    shape : (H, W) of the texture's level 0.

    Returns
    -------
    major, minor : numpy.ndarray, shape (...)
    direction : numpy.ndarray, shape (..., 2), unit vectors (texel space, (x, y)).
    """
    j = as_float_array(dudv, "dudv", ndim_min=2)
    if j.shape[-2:] != (2, 2):
        raise PrefilterError(f"dudv: expected shape (..., 2, 2), got {j.shape}")
    h, w = shape
    flat = np.ascontiguousarray(j.reshape(-1, 2, 2))
    out = np.empty((flat.shape[0], 4))
    serial(footprint_axes_kernel, len(out))(int(h), int(w), flat, out)
    out = out.reshape(j.shape[:-2] + (4,))
    return out[..., 0], out[..., 1], out[..., 2:]


def lod_from_footprint(dudv, shape, *, anisotropic: bool = False, max_aniso: int = 8):
    """Level of detail for a footprint: ``log2`` of the major axis in texels (isotropic), or of
    ``max(minor, major / max_aniso)`` (anisotropic), clamped below at 0. Shape ``(...)``."""
    major, minor, _ = footprint_axes(dudv, shape)
    if anisotropic:
        return _log2_lod(np.maximum(minor, major / as_positive_int(max_aniso, "max_aniso")))
    return _log2_lod(major)


def moment_chain(data) -> MipChain:
    """Mip chain of first and second moments of a scalar ``(H, W)`` / ``(H, W, 1)`` map (channels
    ``E[x], E[x^2]``) or of a 2D map ``(H, W, 2)`` such as slopes (channels
    ``E[x], E[y], E[x^2], E[y^2], E[xy]``)."""
    a = as_float_array(data, "data", ndim_min=2)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        return MipChain(np.stack([a, a * a], -1))
    if a.ndim == 3 and a.shape[2] == 2:
        x, y = a[..., 0], a[..., 1]
        return MipChain(np.stack([x, y, x * x, y * y, x * y], -1))
    raise PrefilterError(f"data: expected shape (H, W), (H, W, 1) or (H, W, 2), got {a.shape}")


def moments_to_stats(m) -> tuple[np.ndarray, np.ndarray]:
    """Mean and (co)variance from looked-up moments.

    ``m (..., 2)`` -> mean ``(...)``, variance ``(...)``; ``m (..., 5)`` -> mean ``(..., 2)``,
    covariance ``(..., 2, 2)``. Negative variances from rounding are clamped to 0.
    """
    m = as_float_array(m, "moments", ndim_min=1)
    if m.shape[-1] == 2:
        return m[..., 0], np.maximum(m[..., 1] - m[..., 0] ** 2, 0.0)
    if m.shape[-1] == 5:
        mx, my = m[..., 0], m[..., 1]
        cxx = np.maximum(m[..., 2] - mx * mx, 0.0)
        cyy = np.maximum(m[..., 3] - my * my, 0.0)
        cxy = m[..., 4] - mx * my
        cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)
        return np.stack([mx, my], -1), cov
    raise PrefilterError(f"moments: expected shape (..., 2) or (..., 5), got {m.shape}")
