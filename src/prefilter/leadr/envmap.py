"""Lat-long environment maps: a solid-angle-weighted mip chain with LOD lookups, and order-2
spherical-harmonic irradiance (Ramamoorthi & Hanrahan 2001; LEADR "Simplified Algorithm 2") and
its exact counterpart, a tabulated irradiance map (:class:`IrradianceMap`).

Convention: ``w = (sin(theta) cos(phi), sin(theta) sin(phi), cos(theta))`` with z up; row ``i`` of
an ``(H, W, C)`` map holds ``theta = (i + 0.5) pi / H``, column ``j`` holds
``phi = (j + 0.5) 2 pi / W``. Lookups wrap in phi and clamp in theta.

Scene environment lights (world y up) map world directions ``d`` to these map coordinates by
:data:`ENV_FROM_WORLD`: ``w = (d_z, -d_x, d_y)``, i.e. ``u = 0`` looks towards +z, ``u = 1/4``
towards -x, ``u = 1/2`` towards -z (the image centre), ``u = 3/4`` towards +x, ``v = 0`` is +y.
Seen from inside, facing the image centre, +x is on the right as in the image (a panorama, not
its mirror image), which makes the map an improper (det -1) change of coordinates; lookups and
SH irradiance only need it orthogonal.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.jit import njit_inline
from prefilter.texture.fetch import CLAMP_V, pack_levels, trilinear
from prefilter.validation import (
    as_directions,
    as_float_array,
    as_positive_int,
    broadcast_batch,
    check_memory,
    check_scalar,
)

#: World (y up) -> lat-long map coordinates of scene environment lights (rows: map x, y, z).
ENV_FROM_WORLD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def latlong_uv(x, y, z):
    """``(u, v) = (phi / 2 pi, theta / pi)`` of directions ``(x, y, z)`` (arrays or scalars;
    ``u`` in ``[0, 1)``)."""
    theta = np.arccos(np.minimum(np.maximum(z, -1.0), 1.0))
    phi = np.arctan2(y, x) % (2.0 * np.pi)
    return phi / (2.0 * np.pi), theta / np.pi


#: :func:`latlong_uv` compiled for kernels (scalars).
latlong_uv_jit = njit_inline(latlong_uv)


def direction_to_uv(w) -> np.ndarray:
    """Continuous texel coordinates ``(..., 2)`` = (column, row) / size in [0, 1)."""
    w = np.asarray(w, dtype=np.float64)
    return np.stack(latlong_uv(w[..., 0], w[..., 1], w[..., 2]), -1)


def texel_directions(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel-centre directions ``(h, w, 3)`` and exact texel solid angles ``(h, w)``."""
    theta_edges = np.linspace(0.0, np.pi, h + 1)
    theta = 0.5 * (theta_edges[:-1] + theta_edges[1:])
    phi = (np.arange(w) + 0.5) * 2.0 * np.pi / w
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), ct), -1)
    omega = (np.cos(theta_edges[:-1]) - np.cos(theta_edges[1:]))[:, None] * (2.0 * np.pi / w)
    return d, np.broadcast_to(omega, (h, w)).copy()


def latlong_resample(image, rows: int) -> np.ndarray:
    """Bilinear resampling ``(rows, 2 rows, C)`` of a lat-long image ``(H, W, C)`` at the new
    texel centres (wrap in u, clamp in v); used to bring any equirectangular file to the
    power-of-two ``(H, 2H)`` shape of :class:`EnvMap`."""
    a = as_float_array(image, "image", ndim_min=3)
    rows = as_positive_int(rows, "rows")
    v = (np.arange(rows) + 0.5) / rows
    u = (np.arange(2 * rows) + 0.5) / (2 * rows)
    uv = np.stack(np.broadcast_arrays(u[None, :], v[:, None]), -1)
    return trilinear(pack_levels([a]), uv, 0.0, clamp=CLAMP_V)


def env_from_image(image, scale: float = 1.0) -> EnvMap:
    """:class:`EnvMap` of an equirectangular image ``(H, W[, C])`` of any size, times ``scale``.

    Grey images give three equal channels, alpha is dropped; sizes that are not ``(2^k, 2^(k+1))``
    are resampled bilinearly up to the next power-of-two height (``>= max(H, W / 2)``).
    """
    a = as_float_array(image, "image", ndim_min=2)
    scale = check_scalar(scale, "scale", lo=0.0)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4) or min(a.shape[:2]) < 1:
        raise PrefilterError(f"image: expected an (H, W, C) image with C in 1..4, got {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise PrefilterError("image: expected finite non-negative radiance")
    a = np.repeat(a[..., :1], 3, axis=2) if a.shape[2] <= 2 else a[..., :3]
    h, w = a.shape[:2]
    rows = 1 << max(1, int(np.ceil(np.log2(max(h, w / 2.0)))))
    if (h, w) != (rows, 2 * rows):
        a = latlong_resample(a, rows)
    with np.errstate(over="ignore"):
        a = a * scale
    if not np.all(np.isfinite(a)):
        raise PrefilterError(f"scale: expected finite radiance times the scale, got inf with "
                             f"scale {scale:g}")
    return EnvMap(a)


class EnvMap:
    """Lat-long radiance ``(H, W, C)`` (``W = 2 H``, powers of two) with a prefiltered mip chain.

    Level ``l`` averages aligned ``2^l x 2^l`` blocks weighted by texel solid angle, so each coarse
    texel holds the mean radiance over its solid angle.
    """

    def __init__(self, radiance):
        a = as_float_array(radiance, "radiance", ndim_min=2)
        if a.ndim == 2:
            a = a[..., None]
        h, w = a.shape[:2]
        if a.ndim != 3 or w != 2 * h or h < 2 or (h & (h - 1)):
            raise PrefilterError(
                "radiance: expected a lat-long map (H, 2H[, C]) with H a power of two, got "
                f"{a.shape}"
            )
        _, omega = texel_directions(h, w)
        self._packed = None
        self.levels = [a]
        self.solid_angles = [omega]
        while a.shape[0] > 1:
            wa = a * omega[..., None]
            om = omega[0::2, 0::2] + omega[1::2, 0::2] + omega[0::2, 1::2] + omega[1::2, 1::2]
            s = wa[0::2, 0::2] + wa[1::2, 0::2] + wa[0::2, 1::2] + wa[1::2, 1::2]
            a, omega = s / om[..., None], om
            self.levels.append(a)
            self.solid_angles.append(omega)

    @property
    def size(self) -> int:
        """Rows ``H`` of level 0."""
        return self.levels[0].shape[0]

    @property
    def texel_solid_angle(self) -> float:
        """Solid angle of an equatorial level-0 texel, ``~ pi^2 / H^2``."""
        h = self.size
        return np.pi / h * 2.0 * np.sin(np.pi / (2 * h))

    @property
    def packed(self):
        """The levels packed for compiled lookups (:func:`prefilter.texture.fetch.pack_levels`)."""
        if self._packed is None:
            self._packed = pack_levels(self.levels)
        return self._packed

    def lookup(self, w, lod=0.0) -> np.ndarray:
        """Trilinear radiance ``(..., C)`` in unit directions ``w (..., 3)`` at mip level ``lod``
        ``(...)`` (broadcast with ``w``; clamped to the chain, ``+-inf`` included)."""
        w = as_directions(w, "w")
        try:
            lod = np.asarray(lod, dtype=np.float64)
        except (TypeError, ValueError):
            raise PrefilterError(f"lod: expected numbers (mip levels), got {lod!r}") from None
        if np.any(np.isnan(lod)):
            raise PrefilterError("lod: expected mip levels (numbers or +-inf), got NaN")
        uv = direction_to_uv(w)
        broadcast_batch(w=uv.shape[:-1], lod=lod.shape)
        return trilinear(self.packed, uv, lod, clamp=CLAMP_V)


# -- order-2 spherical harmonics ---------------------------------------------------------------

#: Real SH basis constants for l <= 2 (Ramamoorthi & Hanrahan 2001 eq. 3).
_Y = (0.282095, 0.488603, 1.092548, 0.315392, 0.546274)
#: Clamped-cosine convolution factors A_l (Ramamoorthi & Hanrahan 2001 eq. 8).
_A = (np.pi, 2.0 * np.pi / 3.0, np.pi / 4.0)


def sh9_basis(w) -> np.ndarray:
    """Real SH basis ``(..., 9)`` for l <= 2, order (00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22)."""
    w = np.asarray(w, dtype=np.float64)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([
        np.full_like(x, _Y[0]),
        _Y[1] * y, _Y[1] * z, _Y[1] * x,
        _Y[2] * x * y, _Y[2] * y * z, _Y[3] * (3.0 * z * z - 1.0), _Y[2] * x * z,
        _Y[4] * (x * x - y * y),
    ], -1)


def sh9_project(env: EnvMap) -> np.ndarray:
    """SH coefficients ``(9, C)`` of the radiance (midpoint quadrature over the texels)."""
    d, omega = texel_directions(*env.levels[0].shape[:2])
    return np.einsum("hwk,hwc->kc", sh9_basis(d) * omega[..., None], env.levels[0])


def sh9_directional(directions, radiance) -> np.ndarray:
    """SH coefficients ``(9, C)`` of directional lights (Simplified Algorithm 2's light loop).

    ``directions (K, 3)`` unit vectors towards the lights, ``radiance (K, C)``: each light is a
    delta of integral ``radiance`` in its direction.
    """
    d = as_float_array(directions, "directions", ndim_min=2, last_dim=3)
    r = as_float_array(radiance, "radiance", ndim_min=2)
    return np.einsum("kj,kc->jc", sh9_basis(d), r)


def sh9_irradiance(coeffs, n) -> np.ndarray:
    """Irradiance ``E(n) = integral L(w) max(0, n.w) dw`` ``(..., C)`` from SH ``coeffs (9, C)``.

    Ramamoorthi & Hanrahan 2001 eq. 7 (order-2 truncation; exact for radiance of order <= 2).
    ``coeffs (9,)`` is one channel (``C = 1``); ``n (..., 3)`` normals (unit for eq. 7). Negative
    values of the truncation are clamped to 0 (irradiance of radiance >= 0 is >= 0).
    """
    c = as_float_array(coeffs, "coeffs", ndim_min=1)
    if c.shape[0] != 9 or c.ndim > 2:
        raise PrefilterError(f"coeffs: expected SH coefficients of shape (9, C) or (9,), got "
                             f"shape {c.shape}")
    c = c.reshape(9, -1)
    # not renormalised: the naive methods pass mip-averaged (shorter) normals on purpose
    n = as_float_array(n, "n", ndim_min=1, last_dim=3)
    a = np.array([_A[0], _A[1], _A[1], _A[1], _A[2], _A[2], _A[2], _A[2], _A[2]])
    # Clamped at 0: the order-2 truncation rings below zero away from a strong light (one
    # directional light: -0.040 at 122 deg vs 17/16 at 0), which would make negative pixels.
    return np.maximum(sh9_basis(n) @ (a[:, None] * c), 0.0)


# -- irradiance map (the exact alternative to order-2 SH) ---------------------------------------

#: Meridian intervals of :class:`IrradianceMap` (node spacing 1.4 degrees): 0.026 % largest
#: error vs quadrature of the 256-row map on ``procedural_env(256)`` (64: 0.09 %, 32: 0.32 %;
#: order-2 SH: 7.7 %, rms 2.2 %).
IRRADIANCE_ROWS = 128
#: The quadrature reads the environment's finest mip level with at most this many rows.
IRRADIANCE_SOURCE_ROWS = 128


class IrradianceMap:
    """Irradiance ``E(n) = integral L(w) max(0, n.w) dw`` of an :class:`EnvMap` tabulated on a
    lat-long *node* grid and read bilinearly: the exact counterpart of :func:`sh9_irradiance`
    (Ramamoorthi & Hanrahan 2001 eq. 1 without the order-2 truncation).

    Nodes: ``theta_i = i pi / R`` (i = 0..R, both poles included, so interpolation near a pole
    is between the pole's own value and the first ring, second-order accurate everywhere) and
    ``phi_j = 2 pi j / (2 R)`` (wrapping); ``R = min(rows, source rows)``. Values by midpoint
    quadrature over the texels of the environment's finest level with at most ``source_rows``
    rows (texel means and exact texel solid angles: the clamped cosine is the only quadrature
    error), computed per ring pair as a circular correlation in phi by FFT (~0.1-0.5 s for
    128 source rows).
    """

    def __init__(self, env: EnvMap, rows: int = IRRADIANCE_ROWS,
                 source_rows: int = IRRADIANCE_SOURCE_ROWS):
        if not isinstance(env, EnvMap):
            raise PrefilterError(f"env: expected a prefilter.leadr.EnvMap, got "
                                 f"{type(env).__name__}")
        self.rows = as_positive_int(rows, "rows", lo=2)
        source_rows = as_positive_int(source_rows, "source_rows")
        lev = next((a for a in env.levels if a.shape[0] <= source_rows), env.levels[-1])
        hs, ws = lev.shape[:2]
        # node columns must fall on source column boundaries (both counts are powers of two)
        self.rows = min(self.rows, hs)
        edges = np.linspace(0.0, np.pi, hs + 1)
        theta_s = 0.5 * (edges[:-1] + edges[1:])
        _, omega = texel_directions(hs, ws)
        theta = np.linspace(0.0, np.pi, self.rows + 1)
        # E(theta_i, phi) = sum_r sum_c K_ir(phi_c - phi) L_rc, a circular correlation in phi
        # per (node ring, source ring), by FFT: K_ir(t) = max(0, n(theta_i, 0).d(theta_r, t))
        # Omega_r at the source column offsets t = (c + 1/2) 2 pi / W.
        t = (np.arange(ws) + 0.5) * (2.0 * np.pi / ws)
        cos_nd = (np.sin(theta)[:, None, None] * np.sin(theta_s)[None, :, None] * np.cos(t)
                  + np.cos(theta)[:, None, None] * np.cos(theta_s)[None, :, None])
        k_hat = np.fft.rfft(np.maximum(cos_nd, 0.0) * omega[None, :, :1], axis=-1)
        l_hat = np.fft.rfft(lev, axis=1)  # (hs, F, C)
        e = np.fft.irfft(np.einsum("irf,rfc->ifc", np.conj(k_hat), l_hat), n=ws, axis=1)
        self.values = np.ascontiguousarray(e[:, ::ws // (2 * self.rows)])

    def lookup(self, n) -> np.ndarray:
        """Irradiance ``(..., C)`` for normals ``n (..., 3)`` (normalised here; map frame)."""
        n = as_float_array(n, "n", ndim_min=1, last_dim=3)
        ln = np.linalg.norm(n, axis=-1)
        if not np.all(np.isfinite(ln) & (ln > 0)):
            raise PrefilterError("n: expected non-zero finite normals")
        r, w = self.rows, 2 * self.rows
        theta = np.arccos(np.clip(n[..., 2] / ln, -1.0, 1.0))
        phi = np.arctan2(n[..., 1], n[..., 0]) % (2.0 * np.pi)
        y = theta * (r / np.pi)
        x = phi * (w / (2.0 * np.pi))
        y0 = np.minimum(np.floor(y), r - 1).astype(np.int64)
        x0 = np.floor(x).astype(np.int64)
        fy, fx = (y - y0)[..., None], (x - x0)[..., None]
        x0, x1 = x0 % w, (x0 + 1) % w
        v = self.values
        top = v[y0, x0] * (1 - fx) + v[y0, x1] * fx
        bot = v[y0 + 1, x0] * (1 - fx) + v[y0 + 1, x1] * fx
        return top * (1 - fy) + bot * fy


def procedural_env(size: int = 64) -> np.ndarray:
    """A test environment ``(size, 2 size, 3)``: sky gradient, warm sun, ground, window stripes.

    Deterministic, with sharp features (sun, stripes) so that prefiltering matters. ``size``: an
    integer >= 1 whose arrays fit :func:`prefilter.validation.check_memory`.
    """
    size = as_positive_int(size, "size")
    # directions, solid angles and about ten rgb temporaries, float64
    check_memory(2 * size * size * 8 * 40, f"size: a procedural {size} x {2 * size} environment")
    d, _ = texel_directions(size, 2 * size)
    z = d[..., 2]
    sky = np.stack([0.3 + 0.2 * z, 0.45 + 0.25 * z, 0.8 + 0.2 * z], -1) * (z[..., None] > 0)
    ground = np.array([0.25, 0.2, 0.15]) * (z[..., None] <= 0)
    sun_dir = np.array([0.5, 0.3, 0.81])
    sun_dir /= np.linalg.norm(sun_dir)
    sun = np.exp(80.0 * (d @ sun_dir - 1.0))[..., None] * np.array([20.0, 17.0, 12.0])
    phi = np.arctan2(d[..., 1], d[..., 0])
    stripes = ((np.abs(z) < 0.4) & (np.cos(12.0 * phi) > 0.6))[..., None] * 2.0
    return sky + ground + sun + stripes
