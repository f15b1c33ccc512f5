"""LEADR moment maps: per-texel slope moments, their mips, and the shading statistics.

Slope convention (same as ``prefilter.microfacet.Beckmann`` and ``prefilter.texture``): a surface
``z = h(x, y)`` has slope ``s = grad h = (dh/dx, dh/dy)``, and its normal is
``n = normalize(-s_x, -s_y, 1)``, i.e. ``s = (-n_x / n_z, -n_y / n_z)`` (LEADR supplemental 1.1).
``x`` runs along image columns (u), ``y`` along rows (v).

The five moments ``E[x], E[y], E[x^2], E[y^2], E[xy]`` are linear in the texels, so every mip level
is the plain box average of level 0 (Olano & Baker 2010; Dupuy et al. 2013 section 4). At shading,
the slope covariance is ``second moments - mean^2`` (clamped to the positive semi-definite cone,
because quantisation or interpolation can break ``E[x^2] >= E[x]^2``) plus ``base_roughness^2 I``:
``base_roughness`` is the standard deviation of the micro-slopes per axis below the texel scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prefilter.validation import SLOPE_MAX, as_float_array, broadcast_batch, check_scalar
from prefilter.errors import PrefilterError
from prefilter.texture.mip import MipChain

#: Channel order of a moment map (and of the baked EXR files).
CHANNELS = ("E_x", "E_y", "E_xx", "E_yy", "E_xy")

#: Smallest accepted ``base_roughness``: keeps the shading covariance positive definite.
MIN_BASE_ROUGHNESS = 1e-3


def _positive_float(x, name: str, *, lo: float = 0.0, closed: bool = False) -> float:
    return check_scalar(x, name, lo=lo, lo_open=not closed)


def slopes_from_height(height, texel_size: float = 1.0) -> np.ndarray:
    """Slopes ``(H, W, 2)`` of a periodic height map ``(H, W)`` by central differences.

    ``texel_size`` is the texel spacing in the units of the heights (heights in texels: 1).
    Central differences keep the mean slope of the whole (tiling) map exactly 0.
    """
    h = as_float_array(height, "height_map", ndim_min=2)
    if h.ndim == 3 and h.shape[2] == 1:
        h = h[..., 0]
    if h.ndim != 2:
        raise PrefilterError(f"height_map: expected shape (H, W), got {h.shape}")
    t = _positive_float(texel_size, "texel_size")
    sx = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) / (2.0 * t)
    sy = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) / (2.0 * t)
    return np.stack([sx, sy], axis=-1)


def slopes_from_normals(normals) -> np.ndarray:
    """Slopes ``s = (-n_x / n_z, -n_y / n_z)`` ``(..., 2)`` of tangent-space normals ``(..., 3)``.

    Normals need not be unit length (slopes are scale invariant) but must point up (``n_z > 0``).
    """
    _not_colours(normals, "normal_map")
    n = as_float_array(normals, "normal_map", ndim_min=1, last_dim=3)
    nz = n[..., 2]
    if np.any(nz <= 0.0):
        raise PrefilterError(
            f"normal_map: expected normals with n_z > 0 (tangent space, z up), got "
            f"{int(np.sum(nz <= 0.0))} texels with n_z <= 0 (min n_z = {nz.min():.4g})"
        )
    return -n[..., :2] / nz[..., None]


def _not_colours(normals, name: str) -> None:
    """Integer arrays are 8/16-bit normal-map colours, not normals: they would give garbage
    slopes silently (every colour has n_z > 0)."""
    dtype = getattr(normals, "dtype", None)
    if dtype is not None and (np.issubdtype(dtype, np.integer) or dtype == np.bool_):
        raise PrefilterError(
            f"{name}: expected tangent-space normals (floats), got an integer ({dtype}) array: "
            "decode normal-map colours first with prefilter.texture.decode_normals(rgb, "
            "convention)")


@dataclass(frozen=True)
class LeadrMaps:
    """Moment mip chain ``chain`` (5 channels, :data:`CHANNELS`) and the sub-texel roughness."""

    chain: MipChain
    base_roughness: float

    def lookup(self, uv, lod=0.0) -> tuple[np.ndarray, np.ndarray]:
        """Mean slope ``(..., 2)`` and covariance ``(..., 2, 2)`` at ``uv (..., 2)`` and ``lod``."""
        return shading_stats(self.chain.lookup(uv, lod), self.base_roughness)


def moments(data, texel_size: float = 1.0, base_roughness: float = 0.0, *,
            band_rows: int | None = None, map_fn=map) -> LeadrMaps:
    """LEADR moment maps of a height map, a slope map or a normal map.

    Dupuy et al. 2013, section 4 (LEAN mapping, Olano & Baker 2010).

    Parameters
    ----------
    data : array_like or prefilter.texture.HeightMap
        ``(H, W)`` heights (slopes by central differences, :func:`slopes_from_height`),
        ``(H, W, 2)`` slopes, ``(H, W, 3)`` tangent-space normals, or a ``HeightMap`` (its exact
        slopes are used). H and W powers of two (mips).
    texel_size : float
        Texel spacing in height units (heights only).
    base_roughness : float
        Standard deviation of the sub-texel slopes per axis, added at shading (``>= 0``; shading
        with 0 is clamped to :data:`MIN_BASE_ROUGHNESS`).
    band_rows : int, optional
        Compute the levels in independent tasks of ``band_rows`` rows of level 0 (a power of
        two; :func:`band_moments`), each run by ``map_fn`` (the built-in ``map``, or
        :meth:`prefilter.distributed.Engine.imap`). The levels are the same bytes as without
        bands: a level-``l`` texel only averages level-0 rows of its own band while
        ``2^l <= band_rows``; the levels below come from the assembled level.

    Returns
    -------
    LeadrMaps
        ``chain.levels[l]`` of shape ``(H >> l, W >> l, 5)``: ``E[x], E[y], E[x^2], E[y^2],
        E[xy]``.
    """
    r = _positive_float(base_roughness, "base_roughness", closed=True)
    name = "data"
    if hasattr(data, "slopes") and hasattr(data, "height"):
        name = "height_map.slopes"
        s = as_float_array(data.slopes, name, ndim_min=3, last_dim=2)
    else:
        a = as_float_array(data, "data", ndim_min=2)
        if a.ndim == 3 and a.shape[-1] == 3:
            _not_colours(data, "data")
        if a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 1):
            s = slopes_from_height(a, texel_size)
        elif a.ndim == 3 and a.shape[2] == 2:
            s = a
        elif a.ndim == 3 and a.shape[2] == 3:
            s = slopes_from_normals(a)
        else:
            raise PrefilterError(
                "data: expected heights (H, W), slopes (H, W, 2) or normals (H, W, 3), got "
                f"{a.shape}"
            )
    h, w = s.shape[:2]
    if s.ndim != 3 or h & (h - 1) or w & (w - 1):
        raise PrefilterError(f"{name}: expected power-of-two height and width (mips), got "
                             f"{h} x {w}")
    if np.any(np.abs(s) > SLOPE_MAX):  # the moments (squares) must stay finite
        raise PrefilterError(f"{name}: expected slopes of magnitude <= {SLOPE_MAX:g}, got max "
                             f"{np.abs(s).max():.4g}")
    if band_rows is None or band_rows >= h:
        return LeadrMaps(MipChain(_moment_texels(s)), r)
    band_rows = int(band_rows)
    if band_rows < 1 or band_rows & (band_rows - 1):
        raise PrefilterError(f"band_rows: expected a power of two >= 1, got {band_rows}")
    depth = band_rows.bit_length() - 1  # levels 0..depth stay inside a band
    bands = [(s[i:i + band_rows], depth) for i in range(0, h, band_rows)]
    parts = list(map_fn(band_moments, *zip(*bands)))
    levels = [np.concatenate([p[lv] for p in parts]) for lv in range(depth + 1)]
    return LeadrMaps(MipChain.from_levels(levels), r)


def _moment_texels(s: np.ndarray) -> np.ndarray:
    """Per-texel moments ``(..., 5)`` (:data:`CHANNELS`) of slopes ``(..., 2)``."""
    x, y = s[..., 0], s[..., 1]
    return np.stack([x, y, x * x, y * y, x * y], axis=-1)


def band_moments(slopes, depth: int) -> list[np.ndarray]:
    """Moment levels ``0..depth`` of a band of rows of a slope map: one independent task of a
    banded bake (:func:`moments` with ``band_rows``). Dupuy et al. 2013, section 4.

    ``slopes (B, W, 2)`` with ``B`` a multiple of ``2^depth``; returns levels
    ``(B >> l, max(W >> l, 1), 5)`` for ``l = 0..depth``.
    """
    return MipChain(_moment_texels(np.asarray(slopes, np.float64))).levels[:depth + 1]


def shading_stats(m, base_roughness: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean slope ``(..., 2)`` and positive definite covariance ``(..., 2, 2)`` from moments.

    ``Sigma = [E[ss^T] - E[s] E[s]^T]_+ + r^2 I`` with ``r = max(base_roughness,``
    :data:`MIN_BASE_ROUGHNESS` ``)`` (Dupuy et al. 2013 eq. 8 with LEAN's base roughness). The
    bracket is projected onto the PSD cone: negative variances become 0 and the correlation is
    clipped to ``|c_xy| <= sqrt(c_xx c_yy)``.
    """
    m = as_float_array(m, "moments", ndim_min=1, last_dim=5)
    r = max(_positive_float(base_roughness, "base_roughness", closed=True), MIN_BASE_ROUGHNESS)
    mx, my = m[..., 0], m[..., 1]
    cxx = np.maximum(m[..., 2] - mx * mx, 0.0)
    cyy = np.maximum(m[..., 3] - my * my, 0.0)
    bound = np.sqrt(cxx * cyy)
    cxy = np.clip(m[..., 4] - mx * my, -bound, bound)
    r2 = r * r
    cov = np.stack([np.stack([cxx + r2, cxy], -1), np.stack([cxy, cyy + r2], -1)], -2)
    return np.stack([mx, my], -1), cov


def stats_to_moments(mean, cov) -> np.ndarray:
    """Inverse of :func:`shading_stats` with ``base_roughness = 0``: moments ``(..., 5)``."""
    mean = as_float_array(mean, "mean", ndim_min=1, last_dim=2)
    cov = as_float_array(cov, "cov", ndim_min=2)
    if cov.shape[-2:] != (2, 2):
        raise PrefilterError(f"cov: expected shape (..., 2, 2), got {cov.shape}")
    broadcast_batch(mean=mean.shape[:-1], cov=cov.shape[:-2])
    mx, my = mean[..., 0], mean[..., 1]
    return np.stack([mx, my, cov[..., 0, 0] + mx * mx, cov[..., 1, 1] + my * my,
                     cov[..., 0, 1] + mx * my], -1)
