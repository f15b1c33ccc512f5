"""Filtered GGX roughness per mip level of a normal map: Toksvig, LEAN and multi-scale LTC.

A mip level averages ``2^k x 2^k`` texels of the normal map; shading it with the averaged (then
renormalised) normal loses the spread of the normals it replaced, so highlights shrink and alias.
Each method folds that spread into the level's roughness ``alpha`` (GGX, the square of perceptual
roughness):

``"toksvig"``
    Toksvig 2005, eq. 3: a Gaussian spread of normals of variance ``sigma^2 = (1 - r) / r``
    (``r = |mean normal|``) scales a Blinn-Phong exponent by ``r / (r + s (1 - r))``, i.e.
    ``1/s' = 1/s + sigma^2``; with the Phong-to-GGX mapping ``s = 2 / alpha^2 - 2`` (Walter et al.
    2007, section 5.2) this is ``alpha'^2 = 2 t / (1 + 2 t)``, ``t = alpha^2 / (2 (1 - alpha^2))
    + sigma^2``.
``"lean"``
    Olano & Baker 2010, eqs. 8-11: slopes ``b = (n_x, n_y) / n_z`` and their second moments are
    mip-averaged; the covariance ``M - B B^T`` plus the base lobe's (``alpha^2 / 2`` per axis, the
    Beckmann slope variance) gives the isotropic ``alpha'^2 = E[alpha^2] + tr(Cov b)``.
``"ltc"``
    Tao et al. 2021, eqs. 4-7: ``alpha_meso`` from the mean resultant length ``r`` and
    ``alpha_total(alpha_micro, alpha_meso)`` (:mod:`prefilter.multiscale`, our refit of eq. 7).

The base roughness of level ``k`` is ``sqrt(E[alpha_0^2])`` over its texels (constant for a
constant roughness); level 0 returns it unchanged (unit normals: ``r = 1``, no slope variance).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.multiscale.convolution import alpha_total
from prefilter.multiscale.meso import alpha_meso
from prefilter.texture.mip import MipChain, moment_chain

__all__ = ["METHODS", "alpha_lean", "alpha_ltc", "alpha_toksvig", "as_normal_field",
           "bake_roughness", "load_normals"]

METHODS = ("toksvig", "lean", "ltc")

#: A texel is "not a normal" when its encoded vector's length is off 1 by more than this ...
UNIT_TOL = 0.2
#: ... and a map with more than this fraction of such texels is not a normal map.
BAD_FRACTION = 0.01

_MIN_NZ = 1e-3  # LEAN's slopes n_xy / n_z: horizon normals are clamped to this height


def _is_pow2(n: int) -> bool:
    return n >= 1 and n & (n - 1) == 0


def as_normal_field(vectors, name: str = "normal map") -> np.ndarray:
    """Unit normals ``(H, W, 3)`` from vectors ``(H, W, >=3)`` that must be a normal map.

    Rejected (one :class:`PrefilterError` naming ``name``): a shape other than ``(H, W, >=3)``,
    non-finite values, more than 1 % of vectors whose length is off 1 by more than 0.2 (an image
    that is not a normal map: a photo, a height or roughness map), any vector with ``z < 0``.
    """
    v = np.asarray(vectors, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] < 3 or min(v.shape[:2]) < 1:
        raise PrefilterError(f"{name}: expected an (H, W, 3) map of normals, got shape {v.shape}")
    v = v[..., :3]
    if not np.all(np.isfinite(v)):
        raise PrefilterError(f"{name}: expected finite normals, got NaN or inf")
    length = np.linalg.norm(v, axis=-1)
    off = np.abs(length - 1.0) > UNIT_TOL
    if off.mean() > BAD_FRACTION:
        raise PrefilterError(
            f"{name}: not a normal map: {100 * off.mean():.1f} % of the texels decode to vectors "
            f"of length outside [{1 - UNIT_TOL:g}, {1 + UNIT_TOL:g}] (median length "
            f"{np.median(length):.3g}); expected unit tangent-space normals")
    if np.any(v[..., 2] < 0.0) or np.any(length == 0.0):
        bad = int(np.sum((v[..., 2] < 0.0) | (length == 0.0)))
        raise PrefilterError(f"{name}: not a normal map: {bad} texel(s) point below the surface "
                             f"(z < 0, blue < 0.5) or are zero; expected tangent-space normals")
    return v / np.maximum(length, 1e-300)[..., None]


def load_normals(spec: str, convention: str = "opengl") -> np.ndarray:
    """Unit normals ``(H, W, 3)`` from a file or a ``procedural:KIND:SIZE[:SEED]`` spec.

    PNG and EXR files hold colours ``(n + 1) / 2`` (green up for ``"opengl"``, down for
    ``"directx"``, :mod:`prefilter.texture.normalmap`); ``.npy`` files hold the vectors.
    """
    if spec.startswith("procedural:"):
        from prefilter.texture.procedural import normal_map

        parts = spec.split(":")[1:]
        try:
            if not 2 <= len(parts) <= 3:
                raise ValueError(spec)
            size, seed = int(parts[1]), int(parts[2]) if len(parts) > 2 else 0
        except ValueError:
            raise PrefilterError(f"NORMALMAP: expected procedural:KIND:SIZE[:SEED], got "
                                 f"{spec!r}") from None
        if seed < 0:
            raise PrefilterError(f"NORMALMAP: expected a SEED >= 0, got {spec!r}")
        return normal_map(parts[0], size=size, seed=seed)
    path = Path(spec)
    if not path.is_file():
        raise PrefilterError(f"NORMALMAP: no such file {spec!r}")
    from prefilter.texture.io import read_image
    from prefilter.texture.normalmap import CONVENTIONS

    if convention not in CONVENTIONS:
        raise PrefilterError(f"convention: expected one of {', '.join(CONVENTIONS)}, got "
                             f"{convention!r}")
    img = read_image(path)
    if img.ndim != 3 or img.shape[2] < 3:
        raise PrefilterError(f"{path}: not a normal map: expected 3 or 4 channels, got "
                             f"{img.shape[2]}")
    v = img[..., :3].copy()
    if path.suffix.lower() != ".npy":
        if v.min() < 0.0 or v.max() > 1.0:
            raise PrefilterError(f"{path}: not a normal map: expected colours (n + 1) / 2 in "
                                 f"[0, 1], got range [{v.min():.4g}, {v.max():.4g}] (raw "
                                 f"vectors go in a .npy file)")
        v = 2.0 * v - 1.0
        if convention == "opengl":
            v[..., 1] = -v[..., 1]
    return as_normal_field(v, str(path))


def alpha_toksvig(r, alpha) -> np.ndarray:
    """Toksvig's filtered GGX roughness ``(...)`` from the mean-normal length ``r (...)`` and the
    base roughness ``alpha (...)`` (Toksvig 2005, eq. 3; module docstring)."""
    r = np.clip(np.asarray(r, dtype=np.float64), 0.0, 1.0)
    a2 = np.clip(np.asarray(alpha, dtype=np.float64), 0.0, 1.0) ** 2
    with np.errstate(divide="ignore"):
        t = a2 / (2.0 * (1.0 - a2)) + (1.0 - r) / r
    return np.sqrt(np.where(np.isfinite(t), 2.0 * t / (1.0 + 2.0 * t), 1.0))


def alpha_lean(slope_moments, alpha2_mean) -> np.ndarray:
    """LEAN's isotropic GGX roughness ``(...)`` from mip-averaged slope moments
    ``(..., 5) = E[b_x], E[b_y], E[b_x^2], E[b_y^2], E[b_x b_y]`` and ``E[alpha^2] (...)``
    (Olano & Baker 2010, eqs. 8-11; module docstring), clamped to ``[0, 1]``."""
    m = np.asarray(slope_moments, dtype=np.float64)
    var = np.maximum(m[..., 2] - m[..., 0] ** 2, 0.0) + np.maximum(m[..., 3] - m[..., 1] ** 2, 0.0)
    return np.sqrt(np.clip(np.asarray(alpha2_mean, dtype=np.float64) + var, 0.0, 1.0))


def alpha_ltc(r, alpha) -> np.ndarray:
    """Multi-scale LTC roughness ``alpha_total(alpha, alpha_meso(r))`` ``(...)`` (Tao et al.
    2021, eqs. 5 and 7, :mod:`prefilter.multiscale`)."""
    r = np.clip(np.asarray(r, dtype=np.float64), 0.0, 1.0)
    return alpha_total(np.clip(alpha, 0.0, 1.0), alpha_meso(r))


def _base_alpha(alpha, shape) -> np.ndarray:
    a = np.asarray(alpha, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(shape, float(a))
    if a.shape != shape:
        raise PrefilterError(f"roughness map: expected the normal map's size {shape[0]} x "
                             f"{shape[1]}, got {a.shape[0]} x {a.shape[1]}" if a.ndim == 2 else
                             f"roughness map: expected an (H, W) map, got shape {a.shape}")
    if not np.all(np.isfinite(a)) or a.min() < 0.0 or a.max() > 1.0:
        raise PrefilterError(f"roughness: expected GGX alpha in [0, 1], got range "
                             f"[{np.nanmin(a):.4g}, {np.nanmax(a):.4g}]")
    return a


def bake_roughness(normals, alpha, method: str = "ltc", *,
                   name: str = "normals") -> list[np.ndarray]:
    """GGX roughness ``alpha`` of every mip level of a normal map.

    Parameters
    ----------
    normals : array_like, shape (H, W, 3)
        Unit tangent-space normals (z up); ``H`` and ``W`` powers of two.
    alpha : float or array_like, shape (H, W)
        Base GGX roughness (the square of perceptual roughness), in ``[0, 1]``.
    method : {"toksvig", "lean", "ltc"}
        See the module docstring.
    name : str
        What error messages call the normal map (e.g. its file name).

    Returns
    -------
    list of numpy.ndarray
        Level ``k`` of shape ``(max(H >> k, 1), max(W >> k, 1))``, down to ``1 x 1``; level 0 is
        ``alpha`` itself.
    """
    if method not in METHODS:
        raise PrefilterError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    n = as_normal_field(normals, name)
    h, w = n.shape[:2]
    if not (_is_pow2(h) and _is_pow2(w)):
        raise PrefilterError(f"{name}: expected power-of-two height and width for a mip "
                             f"chain (DDS / KTX2 levels halve exactly), got {h} x {w}")
    a0 = _base_alpha(alpha, (h, w))
    alpha2 = MipChain(a0 * a0).levels
    if method == "lean":
        b = n[..., :2] / np.maximum(n[..., 2:], _MIN_NZ)
        moments = moment_chain(b).levels
        return [alpha_lean(m, a2[..., 0]) for m, a2 in zip(moments, alpha2)]
    means = MipChain(n).levels
    base = [np.sqrt(a2[..., 0]) for a2 in alpha2]
    r = [np.linalg.norm(m, axis=-1) for m in means]
    f = alpha_toksvig if method == "toksvig" else alpha_ltc
    return [f(rk, ak) for rk, ak in zip(r, base)]
