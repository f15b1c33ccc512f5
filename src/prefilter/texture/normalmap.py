"""Tangent-space normal-map encodings: OpenGL and DirectX green-channel conventions.

Texture space in this package: ``u`` grows along image columns (left to right) and ``v`` along
image rows *as stored in the file* (top to bottom), texel ``(row i, col j)`` covering
``[j, j+1)/W x [i, i+1)/H``. The tangent frame is x = tangent = +u, y = bitangent = +v,
z = geometric normal, and procedural maps are generated directly in it.

A normal-map file stores ``c = (n + 1) / 2``. Its green channel is "image up" in the OpenGL
convention (Y+, e.g. Blender, Maya) and "image down" in the DirectX one (Y-, e.g. Unreal, 3ds
Max). Since ``+v`` points down the image, ``n_y = -(2 g - 1)`` for OpenGL files and
``n_y = 2 g - 1`` for DirectX files.
"""

from __future__ import annotations

import numpy as np

from prefilter._validate import as_float_array
from prefilter.errors import PrefilterError

__all__ = ["CONVENTIONS", "decode_normals", "encode_normals"]

CONVENTIONS = ("opengl", "directx")


def _green_sign(convention: str) -> float:
    if convention not in CONVENTIONS:
        raise PrefilterError(
            f"convention: expected one of {', '.join(CONVENTIONS)}, got {convention!r}")
    return -1.0 if convention == "opengl" else 1.0


def decode_normals(rgb, convention: str = "opengl") -> np.ndarray:
    """Unit tangent-space normals ``(..., 3)`` from colours ``rgb (..., >=3)`` in [0, 1].

    ``n = normalize(2 c - 1)`` with the green channel flipped for ``"opengl"`` (see the module
    docstring); a blue channel
    below 0.5 (normal below the surface) or a zero vector is rejected, as is a non-[0, 1] input.
    """
    c = as_float_array(rgb, "normal map", ndim_min=1)
    if c.shape[-1] < 3:
        raise PrefilterError(f"normal map: expected at least 3 channels, got shape {c.shape}")
    c = c[..., :3]
    if np.any((c < 0.0) | (c > 1.0)):
        raise PrefilterError("normal map: expected colours in [0, 1], got values outside")
    n = 2.0 * c - 1.0
    n[..., 1] *= _green_sign(convention)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    if np.any(length < 1e-6) or np.any(n[..., 2] < 0.0):
        raise PrefilterError("normal map: expected tangent-space normals with z >= 0 (blue >= "
                             "0.5), got zero or downward vectors; is this a normal map?")
    return n / length


def encode_normals(n, convention: str = "opengl") -> np.ndarray:
    """Colours ``(..., 3)`` in [0, 1] storing unit normals ``n (..., 3)``: ``(n + 1) / 2``."""
    n = as_float_array(n, "normals", ndim_min=1, last_dim=3).copy()
    n[..., 1] *= _green_sign(convention)
    return np.clip((n + 1.0) / 2.0, 0.0, 1.0)
