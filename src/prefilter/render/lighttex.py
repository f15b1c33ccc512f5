"""Textured quad lights: a parallelogram quad whose radiance is scaled by an image.

:class:`TexturedQuad` is the light; :class:`LightTexture` holds its image and a prefiltered
pyramid for methods that read it averaged under a lobe (the LTC methods,
:mod:`prefilter.ltc.lighttex`). Level ``l >= 1`` is the *normalised* Gaussian convolution of the
texture restricted to the light, ``G * (L 1_P) / G * 1_P`` with ``sigma_l = 2^(l-1)`` texels, so a
wide filter near an edge averages only texels that emit. Lookups outside the light clamp to its
edge; ``lod`` interpolates linearly between levels, texels bilinearly.

Texture coordinates of a quad light ``v0..v3`` (a parallelogram): ``p = v0 + u (v1 - v0) +
v (v3 - v0)``; ``u`` along image columns, ``v`` along rows (as :class:`prefilter.texture.MipChain`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from prefilter.validation import as_float_array
from prefilter.errors import PrefilterError
from prefilter.texture.fetch import CLAMP_UV, pack_levels, trilinear

__all__ = ["LightTexture", "TexturedQuad", "split_lights", "texture_uv"]


class LightTexture:
    """Prefiltered pyramid of a light texture ``(H, W)`` or ``(H, W, C)`` (linear radiance scale).

    Attributes
    ----------
    levels : list of numpy.ndarray, each ``(H, W, C)``; level 0 is the texture, level ``l`` its
        normalised Gaussian convolution with ``sigma = 2^(l-1)`` texels (module docstring).
    """

    def __init__(self, image):
        from scipy.ndimage import gaussian_filter

        a = as_float_array(image, "light texture", ndim_min=2)
        if a.ndim == 2:
            a = a[..., None]
        if a.ndim != 3 or min(a.shape[:2]) < 1:
            raise PrefilterError(f"light texture: expected shape (H, W) or (H, W, C), got "
                                 f"{a.shape}")
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise PrefilterError("light texture: expected finite values >= 0")
        h, w = a.shape[:2]
        self.levels = [a]
        ones = np.ones((h, w))
        sigma = 1.0
        while True:
            g = gaussian_filter(ones, sigma, mode="constant", truncate=4.0)
            lv = np.stack([gaussian_filter(a[..., c], sigma, mode="constant", truncate=4.0)
                           for c in range(a.shape[2])], -1) / g[..., None]
            self.levels.append(lv)
            if sigma >= 2 * max(h, w):
                break
            sigma *= 2.0

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.levels[0].shape

    @functools.cached_property
    def packed(self):
        """The levels packed for compiled lookups (:func:`prefilter.texture.fetch.pack_levels`)."""
        return pack_levels(self.levels)

    def lookup(self, uv, sigma_texels) -> np.ndarray:
        """Filtered texture ``(N, C)`` at ``uv (N, 2)`` (clamped to the light) with a Gaussian of
        ``sigma_texels (N,)``: ``lod = 1 + log2(sigma)``, linear between levels (0 below 0.5)."""
        uv = as_float_array(uv, "uv", ndim_min=2, last_dim=2).reshape(-1, 2)
        s = np.broadcast_to(as_float_array(sigma_texels, "sigma_texels"), uv.shape[:1])
        # sigma 0.5 -> level 0 (a texel), 1 -> level 1, doubling per level
        lod = np.log2(np.maximum(s, 1e-300) * 2.0)
        return trilinear(self.packed, uv, lod, clamp=CLAMP_UV)


@dataclass(frozen=True)
class TexturedQuad:
    """A parallelogram quad light ``(4, 3)``: constant radiance times a :class:`LightTexture`."""

    vertices: np.ndarray
    radiance: np.ndarray
    texture: LightTexture

    def __post_init__(self):
        from prefilter.render.lights import QuadLight

        q = QuadLight(self.vertices, self.radiance)  # planarity, convexity, rgb checks
        v = q.vertices
        skew = np.linalg.norm(v[0] + v[2] - v[1] - v[3])
        if skew > 1e-6 * max(1.0, np.sqrt(q.area)):
            raise PrefilterError(f"textured quad light vertices: expected a parallelogram "
                                 f"(v0 + v2 = v1 + v3), got {v.tolist()}")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "radiance", q.radiance)

    @property
    def normal(self) -> np.ndarray:
        from prefilter.render.lights import quad_normal_area

        return quad_normal_area(self.vertices)[0]


def texture_uv(vertices, points) -> np.ndarray:
    """Texture coordinates ``(..., 2)`` of ``points (..., 3)`` in the plane of the parallelogram
    ``vertices (..., 4, 3)`` (``p = v0 + u (v1 - v0) + v (v3 - v0)``, least squares off-plane)."""
    v = np.asarray(vertices, float)
    p = np.asarray(points, float) - v[..., 0, :]
    e1, e2 = v[..., 1, :] - v[..., 0, :], v[..., 3, :] - v[..., 0, :]
    g11, g12, g22 = (np.sum(a * b, -1) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.sum(p * e1, -1), np.sum(p * e2, -1)
    det = g11 * g22 - g12 * g12
    return np.stack([(g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det], -1)


def split_lights(scene, method: str):
    """``(LightSet, textured)``: the scene's untextured lights and its textured quads as
    :class:`TexturedQuad`; environment lights are rejected with a message naming ``method``."""
    from prefilter.render.lights import LightSet, QuadLight

    plain = scene.light_set()
    textured, keep = [], []
    for i, spec in enumerate(scene.lights):
        if spec.type == "environment":
            raise PrefilterError(f"lights[{i}]: environment lights are not supported by method "
                                 f"{method!r}; expected quad (textured or not), point or "
                                 "directional lights")
        if spec.type != "quad":
            continue
        if getattr(spec, "texture", None) is None:
            keep.append(QuadLight(spec.vertices, spec.radiance))
        else:
            try:
                textured.append(TexturedQuad(spec.vertices, spec.radiance,
                                             _light_texture(spec.texture)))
            except PrefilterError as exc:
                raise PrefilterError(f"lights[{i}]: {exc}") from None
    return LightSet(quads=tuple(keep), points=plain.points,
                    directionals=plain.directionals), tuple(textured)


_CACHE: dict = {}


def _light_texture(ref) -> LightTexture:
    key = ref.cache_key()
    if key not in _CACHE:
        _CACHE[key] = LightTexture(ref.load())
    return _CACHE[key]
