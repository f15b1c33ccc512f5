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

from prefilter.validation import as_directions, as_float_array
from prefilter.errors import PrefilterError

__all__ = ["CONVENTIONS", "decode_normals", "encode_normals"]

CONVENTIONS = ("opengl", "directx")


def _green_sign(convention: str) -> float:
    if not isinstance(convention, str) or convention not in CONVENTIONS:
        raise PrefilterError(
            f"convention: expected one of {', '.join(CONVENTIONS)}, got {convention!r}")
    return -1.0 if convention == "opengl" else 1.0


def _as_colours(rgb) -> np.ndarray:
    """Colours in [0, 1] from floats, or from 8-/16-bit integers (divided by 255 / 65535)."""
    raw = np.asarray(rgb) if not isinstance(rgb, np.ndarray) else rgb
    if raw.dtype == np.bool_:
        raise PrefilterError("normal map: expected colours (float in [0, 1], uint8 or uint16), "
                             "got a boolean array")
    if np.issubdtype(raw.dtype, np.integer):
        if raw.dtype not in (np.uint8, np.uint16):
            raise PrefilterError(f"normal map: expected 8- or 16-bit unsigned integers (uint8, "
                                 f"uint16) or floats in [0, 1], got dtype {raw.dtype}")
        return raw.astype(np.float64) / np.iinfo(raw.dtype).max
    c = as_float_array(raw, "normal map", ndim_min=1)
    if c.size and (c.min() < 0.0 or c.max() > 1.0):
        lo, hi = float(c.min()), float(c.max())
        hint = ""
        if hi <= 65535.0 and hi > 1.0 and lo >= 0.0:
            hint = ("; integer-valued 8/16-bit data? divide by 255 / 65535 or pass a uint8 / "
                    "uint16 array")
        elif lo >= -1.0 and hi <= 1.0:
            hint = "; already decoded normals in [-1, 1]? pass them directly, not as colours"
        raise PrefilterError(f"normal map: expected colours in [0, 1], got range [{lo:.4g}, "
                             f"{hi:.4g}]{hint}")
    return c


def decode_normals(rgb, convention: str = "opengl") -> np.ndarray:
    """Unit tangent-space normals ``(..., 3)`` from colours ``rgb (..., >=3)``.

    ``n = normalize(2 c - 1)`` with the green channel flipped for ``"opengl"`` (see the module
    docstring). Colours are floats in [0, 1], or ``uint8`` / ``uint16`` arrays (8- and 16-bit
    files), divided by 255 / 65535; extra channels (alpha) are ignored. Quantised colours are
    never exactly unit length, hence the normalisation. A blue channel below 0.5 (normal below
    the surface) or a zero vector is rejected, as is a non-[0, 1] input.
    """
    sign = _green_sign(convention)
    c = _as_colours(rgb)
    if c.ndim == 0 or c.shape[-1] < 3:
        raise PrefilterError(f"normal map: expected at least 3 channels, got shape {c.shape}")
    n = 2.0 * c[..., :3] - 1.0
    n[..., 1] *= sign
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    bad = (length[..., 0] < 1e-6) | (n[..., 2] < 0.0)
    if np.any(bad):
        first = np.argwhere(bad)[0]
        raise PrefilterError(
            f"normal map: expected tangent-space normals with z >= 0 (blue >= 0.5), got "
            f"{int(bad.sum())} zero or downward vectors "
            f"(first at index {tuple(int(i) for i in first)}:"
            f" colour {np.array2string(c[tuple(first)][:3], precision=4)}); is this a normal map?")
    return n / length


def encode_normals(n, convention: str = "opengl") -> np.ndarray:
    """Colours ``(..., 3)`` in [0, 1] storing unit normals ``n (..., 3)``: ``(n + 1) / 2``.

    ``n`` must be unit length (within 1e-3) with ``z >= 0``, what :func:`decode_normals` reads
    back; normalise averaged normals first.
    """
    sign = _green_sign(convention)
    n = as_directions(n, "normals").copy()
    if np.any(n[..., 2] < 0.0):
        raise PrefilterError(f"normals: expected tangent-space normals with z >= 0, got min z "
                             f"{float(n[..., 2].min()):.4g}")
    n[..., 1] *= sign
    return np.clip((n + 1.0) / 2.0, 0.0, 1.0)
